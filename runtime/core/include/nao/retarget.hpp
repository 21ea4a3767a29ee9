// Retargeting, paper Algorithm 1 (eqs. 3-6): per frame, the end-effector-priority pose q_x, the
// joint-priority pose q_q, and the imitation reference q_r (one of the two, chosen by
// RetargetParams::priority; hand priority by default, docs/retargeting.md) of the NAO arm for a scaled
// human hand target x_target and human joint angles q_target. Online version: fixed-size,
// allocation-free, deterministic.
//
// The algorithm (the offline Ceres version, toolchain/retarget_ceres.hpp, runs the same steps):
//   q_goal = q_target clamped to the limits
//   q <- IK(x_target, start: warm start, anchor: q_goal, previous: q_x of the last frame, cost nu)
//                                                               q_x = this first IK solution
//   repeat up to max_outer_iterations:                          (paper eqs. 4 and 6)
//     dq = q_goal - q
//     x_bar = x_target + (1 + lambda_q)^-1 (x(q) + J dq - x_target)
//     x_k <- x(q) + eta_q (x_bar - x(q)), the move capped at max_outer_step_m
//     q <- IK(x_k, start: q, anchor: q_goal, previous: q_q of the last frame)   (paper eq. 5)
//     stop when the change of q is below outer_tolerance
//   q_q = q after the last outer iteration
//   q_r = q_x (priority hand) or q_q (priority joints), after the fallback check below
// The warm start is the previous frame's q_x (the first frame starts from q_goal).
//
// Temporal coherence (docs/retargeting.md). A frame is one tick of a trajectory NAO must execute,
// so from the second frame on the solves also have
//   - a step bound |q_j - q_prev,j| <= v_max,j T (T = step_time_s, v_max the URDF velocity
//     limits), intersected with the joint limits: a box both solvers project onto like the
//     limits. q_prev is the previous frame's pose of the same kind (q_x for the q_x solve, q_q
//     for the outer loop), so q_r never steps faster than the joints can follow, and a target
//     that jumps, or leaves NAO's reach, is approached over as many ticks as the bound needs;
//   - in the q_x solve, a motion cost 1/2 nu sum_j (q_j - q_x,prev,j)^2 with
//     nu = motion_weight x (the previous frame's miss beyond reach_tolerance_m). While the hand
//     reaches its target nu = 0 and q_x is the frame's own solve (the human's posture decides the
//     null space, without lag). Out of reach the miss cannot vanish and its pull on the arm grows
//     with it; among poses that serve the hand about equally (the arm stretched, ElbowYaw and
//     WristYaw turning the 1.2 cm hand offset towards the target) nu keeps the one nearest the
//     previous frame's, so the arm does not swing between equally poor poses. The posture and
//     motion costs fold into one quadratic pull,
//       1/2 sum_j (mu w_j + nu) (q_j - c_j)^2 + const,  c_j = (mu w_j q_goal,j + nu q_prev,j) / (mu w_j + nu),
//     which is how both solvers take it (IkJointTerms).
// The outer loop (q_q) gets the step bound only: its anchor, the human's angles, is continuous
// (human_kinematics.hpp) and its fixed point stays the one below.
//
// What the outer loop converges to. x(q) + J dq is the hand point the joint target would give
// (linearised at q), and lambda_q is the price of moving the hand away from x_target (the
// paper's lambda_q/2 xdot^T xdot with xdot measured from the hand target). At the fixed point q*
// (its hand on x_k):  lambda_q (x(q*) - x_target) = J(q*) (q_goal - q*),  and, to first order,
// x(q*) - x_target = (x(q_goal) - x_target) / (1 + lambda_q): the joint-priority hand lies on the
// segment from the hand target to where the clamped human angles put the hand, 1/(1+lambda_q)
// of the way toward the latter, and the posture is the one nearest the human's that reaches it.
// lambda_q -> 0 gives the clamped human angles (pure joint priority), lambda_q -> infinity q_x.
// So q_q depends on the kinematics and differs from the clamped angles exactly where the hand
// target and the joint targets conflict (tests/test_retarget.cpp checks the fixed-point equation).
// Its convergence is fast: to first order one outer step lands on the fixed point.
//
// Each IK solve is a bounded least-squares problem with a unique local minimiser, the paper's
// displacement term (lambda_x/2 |dq|^2 of eq. 3) made explicit as mu with per-joint posture
// weights w (RetargetParams::posture_weights):
//   min_q 1/2 |p_TH(q) - x|^2 + 1/2 w_p^2 |u_TH(q) - u_target|^2 + 1/2 mu sum_j w_j (q_j - q_anchor,j)^2
//   subject to q_min <= q <= q_max (the URDF limits; from the second frame on, also the step
//   bound, and the motion cost added: "Temporal coherence" above);
// the pointing term is present only when a hand direction target is given. A 5-DoF arm with a
// 3-D target is redundant; mu picks, among the poses that reach the target, the one nearest the
// anchor in the w-weighted metric (the human's posture as the secondary objective in the null
// space), so both solvers converge to the same point. The anchor is the human's joint angles
// (clamped), not the solve's start (the paper's q-dot^T q-dot): with the start as anchor the
// null space is neutral, so q_x wandered by radians over a trajectory, amplifying 1e-8 solver
// differences to 1e-3..1 rad. mu is a price, not an infinitesimal: 1 rad of posture is worth
// sqrt(mu) of hand error. With mu = 1e-6 m^2/rad^2 (1 rad for 1 mm), targets at the rim of the
// workspace (the human's arm straight, NAO's elbow on its 2 deg limit) were reached by twisting
// ElbowYaw/WristYaw 0.5-1.2 rad for one frame to gain 1-2 mm of reach: on held-out whole-arm
// demos 65 % of 10 Hz steps of q_r moved a joint > 0.3 rad (the clamped human angles 32 %).
// mu = 3e-5 (1 rad for 5.5 mm) measured (nao_toolchain gap, 8 held-out demos per movement):
// median hand miss 0.06-0.49 mm, >= 98 % of reachable frames within 1 cm, p99 step 0.88-1.08 rad
// frame by frame, before the step bound (clamp 0.83-0.87). Near a singular direction the hand
// gives way by about mu / (sigma^2 + mu) of the posture pull along it (sigma ~ 0.05 m/rad away
// from the rim: ~1 %).
//
// Fallback: the clamped human angles are always a feasible pose. A solve whose pose puts the hand
// farther from x_target than they do (a capped or failed solve) would be worse than clamping on
// both targets, so that pose is replaced by q_goal and kRetargetFallback is set. With a step
// bound, "the clamped human angles" are those clamped into the frame's box as well: q_goal's
// nearest pose the joints can reach this tick.
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

#include <algorithm>
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
  /// q_x or q_q put the hand farther from x_target than the clamped human angles: replaced by them
  kRetargetFallback = 1u << 7,
  /// The step bound (joint velocity limits x step_time_s) held q_r on a joint this frame. Bit 10:
  /// bits 8 and 9 are the toolchain's row flags (retarget CSV).
  kRetargetStepBound = 1u << 10,
};

/// Where the imitation reference q_r lies on the hand <-> joints trade-off (docs/retargeting.md).
enum class RetargetPriority : std::uint8_t {
  kHand = 0,    ///< q_r = q_x: the hand on x_target, the human's posture in the null space
  kJoints = 1,  ///< q_r = q_q: the human's joint angles first, the hand pulled toward x_target
};

/// "hand" / "joints" (files, CLI, model.bin metadata).
const char* retargetPriorityName(RetargetPriority priority);
/// Parses "hand" / "joints"; false for anything else (priority unchanged).
bool parseRetargetPriority(const char* name, RetargetPriority& priority);

/// Tuning of Algorithm 1; shared by the online LM and the offline Ceres version.
struct RetargetParams {
  double lambda_x = 1e-4;   ///< initial LM damping of each IK solve (paper lambda_x), m^2
  double eta_x = 1.0;       ///< IK step rate (paper eta_x); below 1 slows convergence
  /// Price of moving the hand off x_target in the joint-priority solve (paper lambda_q): the
  /// joint-priority hand misses x_target by 1/(1+lambda_q) of the clamped angles' miss.
  double lambda_q = 0.25;
  double eta_q = 1.0;       ///< outer-loop rate (paper eta_q), 0 < eta_q <= 1
  double max_outer_step_m = 0.02;  ///< cap on the hand target's move per outer iteration, m
  double mu = 3e-5;         ///< displacement weight of each IK solve (price of posture), m^2/rad^2
  /// Per-joint weights w_j of the posture term (which of the human's joints the null space keeps
  /// nearest), dimensionless, > 0; all 1 = the plain Euclidean distance in joint space.
  JointVector posture_weights = JointVector::Ones();
  RetargetPriority priority = RetargetPriority::kHand;  ///< which pose is q_r
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
  /// Motion cost of the q_x solve, m/rad^2: nu = motion_weight x (the previous frame's q_x miss
  /// beyond reach_tolerance_m) prices moving a joint away from the previous frame's pose. Zero
  /// while the hand reaches its target (the solve is the frame's own, the human's posture alone
  /// deciding the null space); out of reach the hand error pulls the arm with a force that grows
  /// with the miss, and so does the price of following it (docs/retargeting.md).
  double motion_weight = 0.005;
  /// Time between two frames, s (the runtime's 10 Hz tick): each frame's q_x and q_q stay
  /// within v_max * step_time_s of the previous frame's (v_max = ArmModel::v_max, the URDF
  /// velocity limits). <= 0: no bound.
  double step_time_s = 0.1;
};

/// What one frame hands to the next.
struct RetargetHistory {
  JointVector q_warm = JointVector::Zero();  ///< start of the next frame's first solve (previous q_x), rad
  bool has_warm_start = false;               ///< false: the next frame starts from q_target clamped
  JointVector q_x = JointVector::Zero();     ///< previous frame's q_x, rad
  JointVector q_q = JointVector::Zero();     ///< previous frame's q_q, rad
  /// false: the next frame has no motion cost and no step bound (the first frame of a sequence,
  /// or after a reset)
  bool has_previous = false;
  double miss_x_m = 0.0;  ///< previous frame's |p_TH(q_x) - x_target|, m (prices the motion cost)
};

/// The joint-space terms of one IK solve: the posture and motion costs folded into one
/// quadratic pull, and the box the solution stays in (retarget.hpp, "Temporal coherence").
struct IkJointTerms {
  JointVector centre = JointVector::Zero();  ///< c: where the pull vanishes, rad
  JointVector weight = JointVector::Zero();  ///< mu w_j + nu per joint, m^2/rad^2
  JointVector lower = JointVector::Zero();   ///< bounds, rad: the joint limits ∩ the step box
  JointVector upper = JointVector::Zero();
};

/// The terms of an IK solve anchored at `q_anchor` (clamped to the limits) and, when
/// `q_previous` is given, with the step bound and the motion cost `nu` (m^2/rad^2) around it.
/// Real-time safe.
IkJointTerms ikJointTerms(const ArmModel& model, const RetargetParams& params, const JointVector& q_anchor,
                          const JointVector* q_previous, double nu = 0.0);

/// Outcome of one frame of Algorithm 1 (both implementations fill the same struct).
struct RetargetResult {
  JointVector q_x = JointVector::Zero();  ///< end-effector priority pose (first IK), rad, inside limits
  JointVector q_q = JointVector::Zero();  ///< joint priority pose (last outer iteration), rad, inside limits
  JointVector q_r = JointVector::Zero();  ///< imitation reference: q_x or q_q by params.priority, rad
  Eigen::Vector3d p_TH_x = Eigen::Vector3d::Zero();  ///< hand point reached by q_x, torso frame, m
  Eigen::Vector3d p_TH_q = Eigen::Vector3d::Zero();  ///< hand point reached by q_q, torso frame, m
  double error_x_m = 0.0;  ///< |p_TH_x - x_target|, m
  double error_clamp_m = 0.0;  ///< |p_TH(q_target clamped) - x_target|: the gap without retargeting, m
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
  ArmData arm;              ///< kinematics workspace
  RetargetHistory history;  ///< warm start and the previous frame's poses
  IkResult ik;              ///< the last IK solve
  RetargetResult result;    ///< the last frame
};

/// Forgets the warm start and the previous frame: the next frame starts from its q_target
/// clamped to the limits, without motion cost or step bound. Real-time safe.
void resetRetarget(RetargetData& data);

/// Sets the warm start (e.g. the robot's measured pose), clamped to the limits, and forgets the
/// previous frame (the next frame has no step bound). Real-time safe.
void resetRetarget(const ArmModel& model, RetargetData& data, const JointVector& q_start);

/// One bounded IK solve (the inner loop of Algorithm 1) toward a hand position, without motion
/// cost or step bound (ikJointTerms(model, params, q_anchor, nullptr)).
/// @param p_target_TH hand point target, torso frame, m (3)
/// @param q_start     start pose, rad (5); clamped to the limits first
/// @param q_anchor    anchor of the displacement term mu, rad (5); clamped to the limits
/// @param u_target_TH optional hand pointing-direction target, torso frame (3, unit);
///                    nullptr = position only
/// @return data.ik.q; data.ik also holds cost, iterations, converged. Real-time safe.
const JointVector& solveHandIk(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                               const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                               const JointVector& q_anchor, const Eigen::Vector3d* u_target_TH = nullptr);

/// The same solve with explicit joint terms (pull and box): `q_start` is clamped into the box.
/// Real-time safe.
const JointVector& solveHandIk(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                               const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                               const IkJointTerms& terms, const Eigen::Vector3d* u_target_TH);

/// One frame of Algorithm 1, warm-started from data.history, with the motion cost and the step
/// bound around the previous frame's poses; it then records this frame's in data.history.
/// @param p_target_TH scaled human hand point x_target (paper eq. 2), torso frame, m (3)
/// @param q_target    human joint angles mapped to NAO's joints, rad (5); may lie outside limits
/// @param u_target_TH optional hand pointing-direction target, torso frame (3; normalised
///                    here, dropped with kRetargetBadPointing if ~0 or non-finite); nullptr = none
/// @return data.result. Non-finite targets: flags kRetargetBadInput, the previous frame's q_x
///         and q_q held (the zero pose clamped if there is none), history unchanged.
///         Never throws. Real-time safe.
const RetargetResult& solveRetarget(const ArmModel& model, const RetargetParams& params, RetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_target,
                                    const Eigen::Vector3d* u_target_TH = nullptr);

namespace detail {

/// The frame-level steps of Algorithm 1 around an IK solver, shared by the online LM and the
/// offline Ceres version so their structure cannot drift apart. `ik(p_target, u_target_or_null,
/// q_start, terms, q_out, iterations) -> converged` must solve the IK problem described at the
/// top of this file with the joint terms `terms` (IkJointTerms). `arm` is a kinematics
/// workspace; `history` the warm start and the previous frame. Writes and returns `result`.
/// Real-time safe when `ik` is.
template <typename IkSolve>
const RetargetResult& runAlgorithm1(const ArmModel& model, const RetargetParams& params, ArmData& arm,
                                    RetargetHistory& history, RetargetResult& result,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_target,
                                    const Eigen::Vector3d* u_target_TH, IkSolve&& ik) {
  result.flags = 0;
  result.iterations_x = 0;
  result.iterations_outer = 0;
  result.iterations_total = 0;

  // In-loop anomaly: hold the previous pose, never throw (a flag in the result).
  if (!p_target_TH.allFinite() || !q_target.allFinite()) {
    result.flags |= kRetargetBadInput;
    if (!history.has_warm_start) {
      result.q_x = clampToLimits(model, JointVector::Zero());
      result.q_q = result.q_x;
      result.q_r = result.q_x;
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
  // arm can take. Its hand miss is the embodiment gap without retargeting.
  const JointVector q_goal = clampToLimits(model, q_target);
  if (!(q_goal.array() == q_target.array()).all()) result.flags |= kRetargetQTargetOutside;
  // Squared task error of the pose of the last forwardKinematics call (position, and the
  // pointing direction when it is a target).
  const double w2 = params.pointing_weight * params.pointing_weight;
  auto taskError2 = [&]() {
    double e = (arm.p_TH - p_target_TH).squaredNorm();
    if (u_use != nullptr) e += w2 * (arm.u_TH - *u_use).squaredNorm();
    return e;
  };
  const Eigen::Vector3d p_TH_goal = forwardKinematics(model, arm, q_goal);
  result.error_clamp_m = (p_TH_goal - p_target_TH).norm();

  // Each pose kind is bounded around its own previous value (top of this file). The bar the
  // fallback check holds a solve to: the clamped human angles, clamped into its box as well.
  const bool has_previous = history.has_previous;
  const double nu =
      has_previous ? params.motion_weight * std::max(0.0, history.miss_x_m - params.reach_tolerance_m) : 0.0;
  const IkJointTerms terms_x = ikJointTerms(model, params, q_goal, has_previous ? &history.q_x : nullptr, nu);
  const IkJointTerms terms_q = ikJointTerms(model, params, q_goal, has_previous ? &history.q_q : nullptr);
  const JointVector q_goal_x = q_goal.cwiseMax(terms_x.lower).cwiseMin(terms_x.upper);
  const JointVector q_goal_q = q_goal.cwiseMax(terms_q.lower).cwiseMin(terms_q.upper);
  const Eigen::Vector3d p_TH_goal_x = forwardKinematics(model, arm, q_goal_x);
  const double task_goal_x = taskError2();
  const Eigen::Vector3d p_TH_goal_q = forwardKinematics(model, arm, q_goal_q);
  const double task_goal_q = taskError2();

  JointVector q = history.has_warm_start ? history.q_warm : q_goal;
  int n_it = 0;
  // End-effector priority: the first IK solve.
  if (!ik(p_target_TH, u_use, JointVector(q), terms_x, q, n_it)) result.flags |= kRetargetXCapHit;
  result.iterations_x = n_it;
  result.iterations_total = n_it;
  result.q_x = q;
  result.p_TH_x = forwardKinematics(model, arm, q);
  result.error_x_m = (result.p_TH_x - p_target_TH).norm();
  if (result.error_x_m > params.reach_tolerance_m) result.flags |= kRetargetXUnreachable;

  // Joint priority (paper eqs. 4, 6): move the hand target from x_target toward the hand point of
  // the joint target, priced by lambda_q, and re-solve the IK (see the top of this file).
  q = q.cwiseMax(terms_q.lower).cwiseMin(terms_q.upper);
  const double keep = 1.0 / (1.0 + params.lambda_q);
  bool outer_converged = false;
  for (int k = 0; k < params.max_outer_iterations; ++k) {
    forwardKinematics(model, arm, q);
    handJacobian(model, arm);
    const JointVector dq = q_goal - q;
    Eigen::Vector3d x_bar = arm.p_TH - p_target_TH;
    x_bar.noalias() += arm.Jp_TH * dq;
    x_bar = p_target_TH + keep * x_bar;
    Eigen::Vector3d move = params.eta_q * (x_bar - arm.p_TH);
    const double move_norm = move.norm();
    if (move_norm > params.max_outer_step_m) move *= params.max_outer_step_m / move_norm;
    const Eigen::Vector3d x_k = arm.p_TH + move;
    Eigen::Vector3d u_k = arm.u_TH;
    if (u_use != nullptr) {
      // The direction follows the same trade-off, linearised the same way.
      Eigen::Vector3d u_bar = arm.u_TH - *u_use;
      u_bar.noalias() += arm.Ju_TH * dq;
      u_k += params.eta_q * (*u_use + keep * u_bar - arm.u_TH);
      u_k.normalize();
    }
    const JointVector q_before = q;
    if (!ik(x_k, u_use != nullptr ? &u_k : nullptr, q_before, terms_q, q, n_it)) result.flags |= kRetargetInnerCapHit;
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

  // Never worse than clamping on both targets: a pose whose hand is farther from x_target than
  // the clamped angles' hand is dominated by them (the clamp is nearest the joint target).
  const double slack = 1e-12;
  forwardKinematics(model, arm, result.q_x);
  if (taskError2() > task_goal_x + slack) {
    result.q_x = q_goal_x;
    result.p_TH_x = p_TH_goal_x;
    result.error_x_m = (p_TH_goal_x - p_target_TH).norm();
    if (params.priority == RetargetPriority::kHand) result.flags |= kRetargetFallback;
  }
  forwardKinematics(model, arm, result.q_q);
  if (taskError2() > task_goal_q + slack) {
    result.q_q = q_goal_q;
    result.p_TH_q = p_TH_goal_q;
    if (params.priority == RetargetPriority::kJoints) result.flags |= kRetargetFallback;
  }
  const bool hand = params.priority == RetargetPriority::kHand;
  result.q_r = hand ? result.q_x : result.q_q;
  if (has_previous) {
    // Which joints the bound holds: those on a face of the step box that is not a joint limit.
    const IkJointTerms& terms = hand ? terms_x : terms_q;
    for (int j = 0; j < kNumJoints; ++j) {
      const bool at_lower = result.q_r[j] <= terms.lower[j] && terms.lower[j] > model.q_min[j];
      const bool at_upper = result.q_r[j] >= terms.upper[j] && terms.upper[j] < model.q_max[j];
      if (at_lower || at_upper) result.flags |= kRetargetStepBound;
    }
  }

  history.q_warm = result.q_x;
  history.has_warm_start = true;
  history.q_x = result.q_x;
  history.q_q = result.q_q;
  history.has_previous = true;
  history.miss_x_m = result.error_x_m;
  return result;
}

}  // namespace detail

}  // namespace nao
