#include "nao/retarget.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace nao {

namespace {

using JointMatrix = Eigen::Matrix<double, kNumJoints, kNumJoints>;

// Damping never drops below this (keeps the normal matrix well scaled) and a run of rejected
// steps that pushes it above the ceiling means no decrease is left in double precision.
constexpr double kLambdaFloor = 1e-15;
constexpr double kLambdaCeiling = 1e20;

// The IK objective at the pose of the last forwardKinematics call in `arm`.
struct IkProblem {
  const Eigen::Vector3d& p_target_TH;
  const Eigen::Vector3d* u_target_TH;
  const JointVector& centre;  // where the joint-space pull vanishes
  const JointVector& mu_w;    // its per-joint weight (posture and motion costs)
  double w;

  double cost(const ArmData& arm) const {
    double c = (arm.p_TH - p_target_TH).squaredNorm() + (mu_w.array() * (arm.q - centre).array().square()).sum();
    if (u_target_TH != nullptr) c += w * w * (arm.u_TH - *u_target_TH).squaredNorm();
    return 0.5 * c;
  }

  // Gradient and Gauss-Newton normal matrix; needs handJacobian at the same pose.
  void normalEquations(const ArmData& arm, JointVector& g, JointMatrix& H) const {
    g.noalias() = arm.Jp_TH.transpose() * (arm.p_TH - p_target_TH);
    H.noalias() = arm.Jp_TH.transpose() * arm.Jp_TH;
    if (u_target_TH != nullptr) {
      g.noalias() += (w * w) * (arm.Ju_TH.transpose() * (arm.u_TH - *u_target_TH));
      H.noalias() += (w * w) * (arm.Ju_TH.transpose() * arm.Ju_TH);
    }
    g.array() += mu_w.array() * (arm.q - centre).array();
    H.diagonal() += mu_w;
  }
};

}  // namespace

const char* retargetPriorityName(RetargetPriority priority) {
  return priority == RetargetPriority::kJoints ? "joints" : "hand";
}

bool parseRetargetPriority(const char* name, RetargetPriority& priority) {
  if (name == nullptr) return false;
  if (std::strcmp(name, "hand") == 0) {
    priority = RetargetPriority::kHand;
    return true;
  }
  if (std::strcmp(name, "joints") == 0) {
    priority = RetargetPriority::kJoints;
    return true;
  }
  return false;
}

void resetRetarget(RetargetData& data) { data.history = RetargetHistory{}; }

void resetRetarget(const ArmModel& model, RetargetData& data, const JointVector& q_start) {
  data.history = RetargetHistory{};
  data.history.q_warm = clampToLimits(model, q_start);
  data.history.has_warm_start = true;
  // A frame with bad input holds data.result: make that the start pose, not a stale or zero one.
  RetargetResult& r = data.result;
  r = RetargetResult{};
  r.q_x = r.q_q = r.q_r = data.history.q_warm;
  r.p_TH_x = r.p_TH_q = forwardKinematics(model, data.arm, data.history.q_warm);
}

IkJointTerms ikJointTerms(const ArmModel& model, const RetargetParams& params, const JointVector& q_anchor,
                          const JointVector* q_previous, double nu) {
  IkJointTerms terms;
  const JointVector anchor = clampToLimits(model, q_anchor);
  const JointVector mu_w = params.mu * params.posture_weights;
  terms.lower = model.q_min;
  terms.upper = model.q_max;
  if (q_previous == nullptr || !(nu > 0.0)) {
    terms.centre = anchor;
    terms.weight = mu_w;
  } else {
    terms.weight = (mu_w.array() + nu).matrix();
    terms.centre = (mu_w.cwiseProduct(anchor) + nu * *q_previous).cwiseQuotient(terms.weight);
  }
  if (q_previous != nullptr && params.step_time_s > 0.0) {
    const JointVector step = params.step_time_s * model.v_max;
    terms.lower = terms.lower.cwiseMax(*q_previous - step);
    terms.upper = terms.upper.cwiseMin(*q_previous + step);
  }
  return terms;
}

const JointVector& solveHandIk(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                               const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                               const JointVector& q_anchor, const Eigen::Vector3d* u_target_TH) {
  return solveHandIk(model, params, data, p_target_TH, q_start, ikJointTerms(model, params, q_anchor, nullptr),
                     u_target_TH);
}

const JointVector& solveHandIk(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                               const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                               const IkJointTerms& terms, const Eigen::Vector3d* u_target_TH) {
  IkResult& ik = data.ik;
  ArmData& arm = data.arm;
  const IkProblem problem{p_target_TH, u_target_TH, terms.centre, terms.weight, params.pointing_weight};
  auto clampToBox = [&](const JointVector& v) -> JointVector { return v.cwiseMax(terms.lower).cwiseMin(terms.upper); };

  JointVector q = clampToBox(q_start);
  forwardKinematics(model, arm, q);
  handJacobian(model, arm);
  double cost = problem.cost(arm);
  JointVector g;
  JointMatrix H;
  problem.normalEquations(arm, g, H);

  double lambda = std::max(params.lambda_x, kLambdaFloor);
  double nu = 2.0;
  ik.converged = false;
  int it = 0;
  while (it < params.max_inner_iterations) {
    // First-order optimality for the box: the projected gradient vanishes.
    const JointVector q_pg = clampToBox(q - g);
    if ((q - q_pg).cwiseAbs().maxCoeff() <= params.gradient_tolerance) {
      ik.converged = true;
      break;
    }
    ++it;

    // Joints at a bound whose descent direction points outward are held; the damped
    // Gauss-Newton step (paper eq. 5) is solved for the others.
    JointMatrix A = H;
    JointVector b = -g;
    for (int j = 0; j < kNumJoints; ++j) {
      const bool held = (q[j] <= terms.lower[j] && g[j] > 0.0) || (q[j] >= terms.upper[j] && g[j] < 0.0);
      if (held) {
        A.row(j).setZero();
        A.col(j).setZero();
        A(j, j) = 1.0;
        b[j] = 0.0;
      } else {
        A(j, j) += lambda;
      }
    }
    const JointVector delta = A.ldlt().solve(b);
    const JointVector q_new = clampToBox(q + params.eta_x * delta);
    const JointVector step = q_new - q;

    // Gain ratio of the actual decrease over the model's prediction for the clamped step.
    const double predicted = -(g.dot(step) + 0.5 * step.dot(H * step));
    forwardKinematics(model, arm, q_new);
    const double cost_new = problem.cost(arm);
    if (predicted > 0.0 && cost_new < cost) {
      const double rho = (cost - cost_new) / predicted;
      q = q_new;
      cost = cost_new;
      handJacobian(model, arm);
      problem.normalEquations(arm, g, H);
      const double t = 2.0 * rho - 1.0;
      lambda = std::max(kLambdaFloor, lambda * std::max(1.0 / 3.0, 1.0 - t * t * t));
      nu = 2.0;
      if (step.cwiseAbs().maxCoeff() < params.step_tolerance) {
        ik.converged = true;
        break;
      }
    } else {
      lambda *= nu;
      nu *= 2.0;
      if (lambda > kLambdaCeiling) {
        // No decrease left at double precision: a numerical minimum.
        ik.converged = true;
        break;
      }
    }
  }
  // Leave `arm` at the solution for callers that read it.
  forwardKinematics(model, arm, q);
  ik.q = q;
  ik.cost = cost;
  ik.iterations = it;
  return ik.q;
}

const RetargetResult& solveRetarget(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_target,
                                    const Eigen::Vector3d* u_target_TH) {
  auto ik = [&](const Eigen::Vector3d& p_goal, const Eigen::Vector3d* u_goal, const JointVector& q_start,
                const IkJointTerms& terms, JointVector& q_out, int& iterations) {
    q_out = solveHandIk(model, params, data, p_goal, q_start, terms, u_goal);
    iterations = data.ik.iterations;
    return data.ik.converged;
  };
  return detail::runAlgorithm1(model, params, data.arm, data.history, data.result, p_target_TH, q_target,
                               u_target_TH, ik);
}

}  // namespace nao
