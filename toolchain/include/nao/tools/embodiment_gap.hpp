// The embodiment gap made measurable (docs/retargeting.md "The gap, measured"): which human DoFs
// draw a demonstration's hand path, and what retargeting changes against the naive mapping
// "the human's joint angles, clamped to NAO's limits".
#pragma once

#include "nao/arm_model.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/synth.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

/// Share of a demonstration's hand-path spread that each human DoF produces, during the circle
/// phase. Per frame t, DoF k moves the endpoint H (palm centre) by dp_k(t) = dH/dq_k (q_k(t) -
/// mean_k), linearised at the phase's mean posture; share_k = sum_t |dp_k|^2 / sum_k sum_t |dp_k|^2.
/// A spread measure: the 8-12 Hz tremor adds path length but almost no spread, the circle all of it.
struct HandPathShares {
  std::array<double, kNumHumanJoints> dof{};  ///< per human DoF (kHumanJointNames order), sums to 1
  double shoulder = 0.0;      ///< shoulder pitch + roll (NAO RShoulderPitch, RShoulderRoll)
  double elbow = 0.0;         ///< humeral rotation + elbow flexion (NAO RElbowYaw, RElbowRoll)
  double forearm = 0.0;       ///< forearm rotation (NAO RWristYaw)
  double wrist = 0.0;         ///< wrist flexion + deviation: the DoFs NAO lacks
  double spread_rms_m = 0.0;  ///< RMS distance of H from its circle-phase mean, m (all DoFs at once)
};

/// Shares of `demo` (synthesiser ground truth). Throws UserError if it has no circle phase.
HandPathShares handPathShares(const SynthDemo& demo);

/// One retargeted frame with a human, beside the naive mapping.
struct GapFrame {
  double t_s = 0.0;
  Eigen::Vector3d x_target = Eigen::Vector3d::Zero();  ///< scaled human hand (paper eq. 2), torso, m
  Eigen::Vector3d p_clamp = Eigen::Vector3d::Zero();   ///< NAO's hand at the clamped human angles, m
  Eigen::Vector3d p_r = Eigen::Vector3d::Zero();       ///< NAO's hand at q_r, m
  JointVector q_clamp = JointVector::Zero();           ///< human angles clamped to the limits, rad
  JointVector q_r = JointVector::Zero();               ///< imitation reference, rad
  bool inside_limits = true;                           ///< q_r within the URDF limits
  bool fallback = false;                               ///< the solve fell back (kRetargetFallback)
  /// false: no pose inside the limits puts the hand within 1 cm of x_target (multi-start search,
  /// handReachable); only searched where q_r itself misses by more than 1 cm.
  bool reachable = true;
};

/// Whether some pose inside the limits puts NAO's hand within `tolerance_m` of `p_target_TH`:
/// bounded IK solves (the runtime's LM, no posture preference to speak of) from `n_starts`
/// poses drawn uniformly in the limits by a generator seeded with `seed`. Deterministic.
bool handReachable(const ArmModel& arm, const Eigen::Vector3d& p_target_TH, double tolerance_m, int n_starts = 64,
                   std::uint64_t seed = 1);

/// The frames of `rows` that have a measured human (held rows are left out); frames where q_r
/// misses x_target by more than 1 cm are searched for reachability (GapFrame::reachable).
std::vector<GapFrame> embodimentGap(const ArmModel& arm, const std::vector<RetargetRow>& rows);

/// The gap in numbers, over one or more sequences of 10 Hz frames.
struct GapSummary {
  int frames = 0;
  double median_clamp_miss_m = 0.0;    ///< median |p_clamp - x_target|
  double median_r_miss_m = 0.0;        ///< median |p_r - x_target|
  double frac_r_within_1cm = 0.0;      ///< share of frames with |p_r - x_target| <= 1 cm
  int unreachable = 0;                 ///< frames no pose inside the limits reaches within 1 cm
  double frac_r_within_1cm_reachable = 0.0;  ///< the same share among the reachable frames
  double median_dq_rad = 0.0;          ///< median |q_r - q_clamp| (Euclidean over the 5 joints)
  std::array<double, kNumJoints> median_abs_dq_joint{};  ///< per joint, median |q_r,j - q_clamp,j|
  /// RMS angular speed of shoulder+elbow joints (0..3) in q_r over that in q_clamp (finite
  /// differences within each sequence, consecutive frames only).
  double speed_ratio_shoulder_elbow = 0.0;
  int outside_limits = 0;              ///< frames with q_r outside the limits
  int fallbacks = 0;                   ///< frames whose solve fell back
  /// Frames where the clamp misses by > 1 cm: share of them where q_r is within 1 cm.
  int clamp_miss_frames = 0;
  double frac_recovered = 0.0;
};

/// Summary over sequences (each a vector of consecutive 10 Hz frames, dt from t_s).
GapSummary summariseGap(const std::vector<std::vector<GapFrame>>& sequences);

/// Per-frame CSV of one or more sequences (docs/formats.md "gap CSV"): seq, t_s, x_target,
/// p_clamp, p_r, q_clamp, q_r. Throws UserError if it cannot be written.
void writeGapCsv(const std::string& path, const std::vector<std::vector<GapFrame>>& sequences);

}  // namespace nao::tools
