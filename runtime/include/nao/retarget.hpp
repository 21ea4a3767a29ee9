// Retargeting, paper Algorithm 1 (eqs. 3-6): per frame, the end-effector-priority pose q_x and
// the joint-priority pose q_q of the NAO arm for a scaled human hand target x_target and human
// joint angles q_target. Online version: fixed-size, allocation-free, deterministic.
//
// The algorithm (the offline Ceres version, toolchain/retarget_ceres.hpp, runs the same steps):
//   q_goal = q_target clamped to the limits
//   q <- IK(x_target, start: warm start, anchor: q_goal)        q_x = this first IK solution
//   repeat up to max_outer_iterations:
//     dq = q_goal - q;  dx = (1 + lambda_q)^-1 J dq                  (paper eq. 6)
//       (dq scaled down so that eta_q/(1+lambda_q) |dq|_inf <= max_outer_step: J dq is a
//        linearisation; unlimited, large joint gaps threw x_k out of reach and the loop wandered)
//     x_k <- x(q) + eta_q dx;  q <- IK(x_k, start: q, anchor: q_goal)  (paper eq. 5)
//     stop when the change of q is below outer_tolerance
//   q_q = q after the last outer iteration
// The warm start is the previous frame's q_x (the first frame starts from q_goal).
//
// Each IK solve is a bounded least-squares problem with a unique local minimiser, the paper's
// displacement term (lambda_x/2 |dq|^2 of eq. 3) made explicit as mu:
//   min_q 1/2 |p_TH(q) - x|^2 + 1/2 w^2 |u_TH(q) - u_target|^2 + 1/2 mu |q - q_anchor|^2
//   subject to q_min <= q <= q_max (the URDF limits);
// the pointing term is present only when a hand direction target is given. A 5-DoF arm with a
// 3-D target is redundant; mu picks, among the poses that reach the target, the one nearest the
// anchor, so both solvers converge to the same point. The anchor is the human's joint angles
// (clamped), not the solve's start (the paper's q-dot^T q-dot): with the start as anchor the
// null space is neutral, so q_x wandered by radians over a trajectory and the outer loop
// crept along the self-motion manifold for dozens of iterations, amplifying 1e-8 solver
// differences to 1e-3..1 rad. With q_goal as anchor the redundancy is resolved toward the
// human's posture, and the outer loop's fixed point is q_goal itself: q_q converges to the
// joint target clamped to the limits (tests: mean distance ~2e-8 rad), the joint-priority
// end of the trade-off, while q_x is the pose nearest q_goal that puts the hand on x_target.
// Price of mu on reach: the hand misses a reachable target by about
// mu |q - q_anchor| / sigma_min(J); with mu = 1e-6 m^2/rad^2 that is ~1e-5 m for a 1 rad
// posture difference at sigma_min ~ 0.05 m/rad (tests: < 1 mm on every warm-started frame).
//
// The solver is a projected Levenberg-Marquardt method (paper eq. 5 with adaptive damping
// lambda, started at lambda_x): joints at a limit whose gradient pushes outward are held, the
// damped Gauss-Newton step is solved for the others, and the candidate is clamped to the
// limits; a step is accepted only if it lowers the cost. So every output is inside the limits
// by construction (clamping, never wrapping). Stops on iteration caps only, never on time.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/kinematics.hpp"

#include <Eigen/Core>

#include <cstdint>

namespace nao {

/// Per-frame status bits of a retarget solve (0 = every solve converged, targets met).
/// Never an exception: a caller reads these and counts them.
enum RetargetFlags : std::uint32_t {
  kRetargetXCapHit = 1u << 0,       ///< the q_x IK solve stopped at max_inner_iterations
  kRetargetXUnreachable = 1u << 1,  ///< q_x misses x_target by more than reach_tolerance_m
  kRetargetQCapHit = 1u << 2,       ///< the outer loop stopped at max_outer_iterations
  kRetargetInnerCapHit = 1u << 3,   ///< an IK solve inside the outer loop hit its cap
  kRetargetBadInput = 1u << 4,      ///< non-finite target: nothing solved, previous pose held
  kRetargetQTargetOutside = 1u << 5,  ///< q_target lies outside the limits (informational)
  kRetargetBadPointing = 1u << 6,   ///< direction target non-finite or ~0: solved position-only
};

/// Tuning of Algorithm 1; shared by the online LM and the offline Ceres version.
struct RetargetParams {
  double lambda_x = 1e-4;   ///< initial LM damping of each IK solve (paper lambda_x), m^2
  double eta_x = 1.0;       ///< IK step rate (paper eta_x); below 1 slows convergence
  double lambda_q = 0.25;   ///< outer-loop damping (paper lambda_q)
  double eta_q = 1.0;       ///< outer-loop rate (paper eta_q): x moves by eta_q/(1+lambda_q) J dq
  double max_outer_step = 0.1;  ///< cap on |eta_q/(1+lambda_q) dq|_inf per outer iteration, rad
  double mu = 1e-6;         ///< displacement weight of each IK solve, m^2/rad^2
  double pointing_weight = 0.05;  ///< w: metres of hand error worth a unit direction error
  /// LM iteration cap per IK solve. Near a straight elbow the displacement term alone fixes
  /// ElbowYaw, a flat valley where 100 iterations left 1e-2 rad unconverged on ~3 % of the
  /// synthetic set's frames; 500 converges them (tests/test_pipeline.cpp).
  int max_inner_iterations = 500;
  int max_outer_iterations = 60;   ///< cap of the joint-priority outer loop
  double gradient_tolerance = 1e-14;  ///< IK converged: projected gradient inf-norm below, m^2/rad
  double step_tolerance = 1e-12;      ///< IK converged: accepted step inf-norm below, rad
  double outer_tolerance = 1e-7;      ///< outer loop converged: change of q inf-norm below, rad
  double reach_tolerance_m = 1e-3;    ///< q_x farther than this from x_target sets kRetargetXUnreachable
};

/// Outcome of one frame of Algorithm 1 (both implementations fill the same struct).
struct RetargetResult {
  JointVector q_x = JointVector::Zero();  ///< end-effector priority pose (first IK), rad, inside limits
  JointVector q_q = JointVector::Zero();  ///< joint priority pose (last outer iteration), rad, inside limits
  Eigen::Vector3d p_TH_x = Eigen::Vector3d::Zero();  ///< hand point reached by q_x, torso frame, m
  Eigen::Vector3d p_TH_q = Eigen::Vector3d::Zero();  ///< hand point reached by q_q, torso frame, m
  double error_x_m = 0.0;  ///< |p_TH_x - x_target|, m
  int iterations_x = 0;    ///< LM iterations of the q_x solve
  int iterations_outer = 0;  ///< outer iterations run
  int iterations_total = 0;  ///< LM iterations of all IK solves of the frame
  std::uint32_t flags = 0;   ///< RetargetFlags bits
};

/// Outcome of one IK solve.
struct IkResult {
  JointVector q = JointVector::Zero();  ///< solution, rad, inside limits
  double cost = 0.0;       ///< final value of the objective above
  int iterations = 0;      ///< LM iterations taken (accepted or rejected)
  bool converged = false;  ///< false: stopped at max_inner_iterations
};

/// Everything the retarget functions write: kinematics workspace, warm start, last results.
/// Build once (configure time); the solve functions only overwrite fields.
struct RetargetData {
  ArmData arm;                              ///< kinematics workspace
  JointVector q_warm = JointVector::Zero(); ///< start of the next frame (previous frame's q_x), rad
  bool has_warm_start = false;              ///< false: the next frame starts from q_target clamped
  IkResult ik;                              ///< the last IK solve
  RetargetResult result;                    ///< the last frame
};

/// Forgets the warm start: the next frame starts from its q_target clamped to the limits.
/// Real-time safe.
void resetRetarget(RetargetData& data);

/// Sets the warm start (e.g. the robot's measured pose), clamped to the limits. Real-time safe.
void resetRetarget(const ArmModel& model, RetargetData& data, const JointVector& q_start);

/// One bounded IK solve (the inner loop of Algorithm 1) toward a hand position.
/// @param p_target_TH hand point target, torso frame, m (3)
/// @param q_start     start pose, rad (5); clamped to the limits first
/// @param q_anchor    anchor of the displacement term mu, rad (5); clamped to the limits
/// @param u_target_TH optional hand pointing-direction target, torso frame (3, unit);
///                    nullptr = position only
/// @return data.ik.q; data.ik also holds cost, iterations, converged. Real-time safe.
const JointVector& solveHandIk(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                               const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                               const JointVector& q_anchor, const Eigen::Vector3d* u_target_TH = nullptr);

/// One frame of Algorithm 1, warm-started from data.q_warm, which it then sets to q_x.
/// @param p_target_TH scaled human hand point x_target (paper eq. 2), torso frame, m (3)
/// @param q_target    human joint angles mapped to NAO's joints, rad (5); may lie outside limits
/// @param u_target_TH optional hand pointing-direction target, torso frame (3; normalised
///                    here, dropped with kRetargetBadPointing if ~0 or non-finite); nullptr = none
/// @return data.result. Non-finite targets: flags kRetargetBadInput, the previous frame's q_x
///         and q_q held (the zero pose clamped if there is none), warm start unchanged.
///         Never throws. Real-time safe.
const RetargetResult& solveRetarget(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_target,
                                    const Eigen::Vector3d* u_target_TH = nullptr);

namespace detail {

/// The frame-level steps of Algorithm 1 around an IK solver, shared by the online LM and the
/// offline Ceres version so their structure cannot drift apart. `ik(p_target, u_target_or_null,
/// q_start, q_anchor, q_out, iterations) -> converged` must solve the IK problem described at the top of
/// this file. `arm` is a kinematics workspace; `q_warm`/`has_warm_start` the warm start state.
/// Writes and returns `result`. Real-time safe when `ik` is.
template <typename IkSolve>
const RetargetResult& runAlgorithm1(const ArmModel& model, const RetargetParams& params, ArmData& arm,
                                    JointVector& q_warm, bool& has_warm_start, RetargetResult& result,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_target,
                                    const Eigen::Vector3d* u_target_TH, IkSolve&& ik) {
  result.flags = 0;
  result.iterations_x = 0;
  result.iterations_outer = 0;
  result.iterations_total = 0;

  // In-loop anomaly: hold the previous pose, never throw (STYLE 5).
  if (!p_target_TH.allFinite() || !q_target.allFinite()) {
    result.flags |= kRetargetBadInput;
    if (!has_warm_start) {
      result.q_x = clampToLimits(model, JointVector::Zero());
      result.q_q = result.q_x;
      result.p_TH_x = forwardKinematics(model, arm, result.q_x);
      result.p_TH_q = result.p_TH_x;
    }
    result.error_x_m = 0.0;
    return result;
  }

  // A direction that is not usable is dropped, not guessed.
  Eigen::Vector3d u_goal = Eigen::Vector3d::UnitX();
  const Eigen::Vector3d* u_use = nullptr;
  if (u_target_TH != nullptr) {
    const double n = u_target_TH->norm();
    if (u_target_TH->allFinite() && n > 1e-9) {
      u_goal = *u_target_TH / n;
      u_use = &u_goal;
    } else {
      result.flags |= kRetargetBadPointing;
    }
  }

  // The joint target the outer loop pulls toward: clamped, so its fixed point is a pose the
  // arm can take.
  const JointVector q_goal = clampToLimits(model, q_target);
  if (!(q_goal.array() == q_target.array()).all()) result.flags |= kRetargetQTargetOutside;

  JointVector q = has_warm_start ? q_warm : q_goal;
  int n_it = 0;
  // End-effector priority: the first IK solve.
  if (!ik(p_target_TH, u_use, JointVector(q), q_goal, q, n_it)) result.flags |= kRetargetXCapHit;
  result.iterations_x = n_it;
  result.iterations_total = n_it;
  result.q_x = q;
  result.p_TH_x = forwardKinematics(model, arm, q);
  result.error_x_m = (result.p_TH_x - p_target_TH).norm();
  if (result.error_x_m > params.reach_tolerance_m) result.flags |= kRetargetXUnreachable;

  // Joint priority: pull x_target toward the joint target (paper eq. 6), re-solve the IK.
  const double rate = params.eta_q / (1.0 + params.lambda_q);
  bool outer_converged = false;
  for (int k = 0; k < params.max_outer_iterations; ++k) {
    forwardKinematics(model, arm, q);
    handJacobian(model, arm);
    JointVector dq = q_goal - q;
    const double step_inf = rate * dq.cwiseAbs().maxCoeff();
    if (step_inf > params.max_outer_step) dq *= params.max_outer_step / step_inf;
    Eigen::Vector3d x_k = arm.p_TH;
    x_k.noalias() += rate * (arm.Jp_TH * dq);
    Eigen::Vector3d u_k = arm.u_TH;
    if (u_use != nullptr) {
      u_k.noalias() += rate * (arm.Ju_TH * dq);
      u_k.normalize();
    }
    const JointVector q_before = q;
    if (!ik(x_k, u_use != nullptr ? &u_k : nullptr, q_before, q_goal, q, n_it)) result.flags |= kRetargetInnerCapHit;
    result.iterations_total += n_it;
    result.iterations_outer = k + 1;
    if ((q - q_before).cwiseAbs().maxCoeff() < params.outer_tolerance) {
      outer_converged = true;
      break;
    }
  }
  if (!outer_converged && params.max_outer_iterations > 0) result.flags |= kRetargetQCapHit;
  result.q_q = q;
  result.p_TH_q = forwardKinematics(model, arm, q);

  q_warm = result.q_x;
  has_warm_start = true;
  return result;
}

}  // namespace detail

}  // namespace nao
