#include "nao/tools/retarget_ceres.hpp"
#include "nao/tools/retarget_pipeline.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace nao::tools {

namespace {

// Ceres' iteration cap per IK solve, in multiples of RetargetParams::max_inner_iterations.
constexpr int kCeresIterationFactor = 4;

constexpr int kPositionResiduals = 3 + kNumJoints;

// Hand position error and the joint-space pull (posture and motion costs, IkJointTerms):
// [p_TH(q) - x_target; sqrt(weight) (q - centre)].
class HandPositionCost final : public ceres::SizedCostFunction<kPositionResiduals, kNumJoints> {
 public:
  HandPositionCost(const ArmModel& model, ArmData& arm, const Eigen::Vector3d& p_target_TH, const IkJointTerms& terms)
      : model_(model), arm_(arm), p_target_TH_(p_target_TH), centre_(terms.centre), sqrt_w_(terms.weight.cwiseSqrt()) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const Eigen::Map<const JointVector> q(parameters[0]);
    forwardKinematics(model_, arm_, JointVector(q));
    Eigen::Map<Eigen::Matrix<double, kPositionResiduals, 1>> r(residuals);
    r.head<3>() = arm_.p_TH - p_target_TH_;
    r.tail<kNumJoints>() = sqrt_w_.cwiseProduct(q - centre_);
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      handJacobian(model_, arm_);
      Eigen::Map<Eigen::Matrix<double, kPositionResiduals, kNumJoints, Eigen::RowMajor>> J(jacobians[0]);
      J.topRows<3>() = arm_.Jp_TH;
      J.bottomRows<kNumJoints>() = sqrt_w_.asDiagonal();
    }
    return true;
  }

 private:
  const ArmModel& model_;
  ArmData& arm_;
  const Eigen::Vector3d p_target_TH_;
  const JointVector centre_;
  const JointVector sqrt_w_;  // sqrt(mu w_j + nu) per joint
};

// Pointing-direction error w (u_TH(q) - u_target).
class HandPointingCost final : public ceres::SizedCostFunction<3, kNumJoints> {
 public:
  HandPointingCost(const ArmModel& model, ArmData& arm, const Eigen::Vector3d& u_target_TH, double w)
      : model_(model), arm_(arm), u_target_TH_(u_target_TH), w_(w) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const Eigen::Map<const JointVector> q(parameters[0]);
    forwardKinematics(model_, arm_, JointVector(q));
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = w_ * (arm_.u_TH - u_target_TH_);
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      handJacobian(model_, arm_);
      Eigen::Map<Eigen::Matrix<double, 3, kNumJoints, Eigen::RowMajor>> J(jacobians[0]);
      J = w_ * arm_.Ju_TH;
    }
    return true;
  }

 private:
  const ArmModel& model_;
  ArmData& arm_;
  const Eigen::Vector3d u_target_TH_;
  const double w_;
};

}  // namespace

void resetRetarget(CeresRetargetData& data) { data.history = RetargetHistory{}; }

namespace {

// Gradient of the IK objective at q (for the active-set check below).
JointVector objectiveGradient(const ArmModel& model, const RetargetParams& params, ArmData& arm,
                              const Eigen::Vector3d& p_target_TH, const Eigen::Vector3d* u_target_TH,
                              const IkJointTerms& terms, const JointVector& q) {
  forwardKinematics(model, arm, q);
  handJacobian(model, arm);
  JointVector g = arm.Jp_TH.transpose() * (arm.p_TH - p_target_TH);
  if (u_target_TH != nullptr) {
    const double w2 = params.pointing_weight * params.pointing_weight;
    g.noalias() += w2 * (arm.Ju_TH.transpose() * (arm.u_TH - *u_target_TH));
  }
  g.array() += terms.weight.array() * (q - terms.centre).array();
  return g;
}

// One Ceres run from q (in place) with the joints in `held` kept constant.
ceres::Solver::Summary runCeres(const ArmModel& model, const RetargetParams& params, ArmData& arm,
                                const Eigen::Vector3d& p_target_TH, const Eigen::Vector3d* u_target_TH,
                                const IkJointTerms& terms, const std::vector<int>& held, double* q) {
  HandPositionCost position_cost(model, arm, p_target_TH, terms);
  HandPointingCost pointing_cost(model, arm, u_target_TH != nullptr ? *u_target_TH : Eigen::Vector3d::UnitX(),
                                 params.pointing_weight);
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  problem.AddResidualBlock(&position_cost, nullptr, q);
  if (u_target_TH != nullptr) problem.AddResidualBlock(&pointing_cost, nullptr, q);
  for (int j = 0; j < kNumJoints; ++j) {
    problem.SetParameterLowerBound(q, j, terms.lower[j]);
    problem.SetParameterUpperBound(q, j, terms.upper[j]);
  }
  if (static_cast<int>(held.size()) == kNumJoints) {
    problem.SetParameterBlockConstant(q);
  } else if (!held.empty()) {
    problem.SetManifold(q, new ceres::SubsetManifold(kNumJoints, held));
  }

  ceres::Solver::Options options;
  options.minimizer_type = ceres::TRUST_REGION;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = ceres::DENSE_QR;
  options.num_threads = 1;
  // Offline, so afford more: in flat valleys (a straight elbow, joints pinned at limits) Ceres'
  // trust-region steps converge more slowly than the online LM it is the reference for.
  options.max_num_iterations = kCeresIterationFactor * params.max_inner_iterations;
  options.initial_trust_region_radius = 1.0 / std::max(params.lambda_x, 1e-15);
  options.gradient_tolerance = params.gradient_tolerance;
  options.parameter_tolerance = params.step_tolerance;
  options.function_tolerance = 1e-16;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  return summary;
}

}  // namespace

const JointVector& solveHandIkCeres(const ArmModel& model, const RetargetParams& params, CeresRetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                                    const JointVector& q_anchor, const Eigen::Vector3d* u_target_TH) {
  return solveHandIkCeres(model, params, data, p_target_TH, q_start, ikJointTerms(model, params, q_anchor, nullptr),
                          u_target_TH);
}

const JointVector& solveHandIkCeres(const ArmModel& model, const RetargetParams& params, CeresRetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                                    const IkJointTerms& terms, const Eigen::Vector3d* u_target_TH) {
  const JointVector q_begin = q_start.cwiseMax(terms.lower).cwiseMin(terms.upper);
  double q[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j) q[j] = q_begin[j];

  // Ceres' bounded LM (projection onto the box) crawls once a joint sits at its limit. So:
  // a bounded solve, then re-solves with the joints that are at a limit and pushed outward
  // held constant (an active set), until that set no longer changes.
  std::vector<int> held;
  ceres::Solver::Summary summary = runCeres(model, params, data.arm_cost, p_target_TH, u_target_TH, terms, held, q);
  int iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  for (int round = 0; round < kNumJoints + 1; ++round) {
    const JointVector q_now = Eigen::Map<const JointVector>(q);
    const JointVector g =
        objectiveGradient(model, params, data.arm_cost, p_target_TH, u_target_TH, terms, q_now);
    std::vector<int> active;
    for (int j = 0; j < kNumJoints; ++j)
      if ((q_now[j] <= terms.lower[j] && g[j] > 0.0) || (q_now[j] >= terms.upper[j] && g[j] < 0.0)) active.push_back(j);
    if (active.empty() || active == held) break;
    held = active;
    summary = runCeres(model, params, data.arm_cost, p_target_TH, u_target_TH, terms, held, q);
    iterations += summary.num_successful_steps + summary.num_unsuccessful_steps;
  }

  // Ceres keeps q inside the bounds; the clamp only guards the contract.
  data.ik.q = Eigen::Map<const JointVector>(q).cwiseMax(terms.lower).cwiseMin(terms.upper);
  data.ik.cost = summary.final_cost;
  data.ik.iterations = iterations;
  data.ik.converged = summary.termination_type == ceres::CONVERGENCE;
  return data.ik.q;
}

const RetargetResult& solveRetargetCeres(const ArmModel& model, const RetargetParams& params,
                                         CeresRetargetData& data, const Eigen::Vector3d& p_target_TH,
                                         const JointVector& q_target, const Eigen::Vector3d* u_target_TH) {
  auto ik = [&](const Eigen::Vector3d& p_goal, const Eigen::Vector3d* u_goal, const JointVector& q_start,
                const IkJointTerms& terms, JointVector& q_out, int& iterations) {
    q_out = solveHandIkCeres(model, params, data, p_goal, q_start, terms, u_goal);
    iterations = data.ik.iterations;
    return data.ik.converged;
  };
  return nao::detail::runAlgorithm1(model, params, data.arm, data.history, data.result, p_target_TH, q_target,
                                    u_target_TH, ik);
}

std::vector<RetargetResult> retargetSequenceLM(const ArmModel& model, const RetargetParams& params,
                                               const std::vector<RetargetFrame>& frames) {
  RetargetData data;
  std::vector<RetargetResult> out;
  out.reserve(frames.size());
  for (const RetargetFrame& f : frames)
    out.push_back(solveRetarget(model, params, data, f.p_target_TH, f.q_target, f.has_pointing ? &f.u_target_TH : nullptr));
  return out;
}

std::vector<RetargetResult> retargetSequenceCeres(const ArmModel& model, const RetargetParams& params,
                                                  const std::vector<RetargetFrame>& frames) {
  CeresRetargetData data;
  std::vector<RetargetResult> out;
  out.reserve(frames.size());
  for (const RetargetFrame& f : frames)
    out.push_back(
        solveRetargetCeres(model, params, data, f.p_target_TH, f.q_target, f.has_pointing ? &f.u_target_TH : nullptr));
  return out;
}

RetargetAgreement compareRetarget(const std::vector<RetargetResult>& a, const std::vector<RetargetResult>& b) {
  if (a.size() != b.size())
    throw std::invalid_argument("compareRetarget: " + std::to_string(a.size()) + " and " + std::to_string(b.size()) +
                                " results cannot be compared frame by frame");
  RetargetAgreement agreement;
  double worst = -1.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    const double dx = (a[i].q_x - b[i].q_x).cwiseAbs().maxCoeff();
    const double dq = (a[i].q_q - b[i].q_q).cwiseAbs().maxCoeff();
    agreement.max_abs_q_x = std::max(agreement.max_abs_q_x, dx);
    agreement.max_abs_q_q = std::max(agreement.max_abs_q_q, dq);
    if (std::max(dx, dq) > worst) {
      worst = std::max(dx, dq);
      agreement.worst_frame = static_cast<int>(i);
    }
  }
  return agreement;
}

// The Ceres-capable sequence: here, not in retarget_pipeline.cpp, so that nao_reference (nao_rt's
// reference library) stays free of Ceres.
std::vector<RetargetRow> retargetSkeleton(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options) {
  if (!options.use_ceres) return retargetSkeletonLm(arm, frames, options);
  RetargetParams params = options.params;
  if (params.step_time_s > 0.0) params.step_time_s = skeletonStepTime(frames, params.step_time_s);
  CeresRetargetData ceres;
  resetRetarget(ceres);
  return retargetSkeletonWith(arm, frames, options,
                              [&](const RetargetFrame& t, const Eigen::Vector3d* u) -> const RetargetResult& {
                                return solveRetargetCeres(arm, params, ceres, t.p_target_TH, t.q_target, u);
                              });
}

}  // namespace nao::tools
