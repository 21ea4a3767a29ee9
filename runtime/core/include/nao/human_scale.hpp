// The human scale constant d_h of a whole demonstration (configure time: a recorded reference,
// the toolchain's retargeting): per-segment medians over
// the frames in which the arm was measured, so one bad frame or a flickering hand detection
// does not move it. Feed the result into HumanKinematicsConfig (scale_m, hand_length_m).
#pragma once

#include "nao/human_kinematics.hpp"
#include "nao/body25.hpp"

namespace nao {

struct HumanArmLengths {
  double upper_arm_m = 0.0;  ///< median |elbow - shoulder|
  double forearm_m = 0.0;    ///< median |wrist - elbow|
  double hand_m = 0.0;       ///< median |hand endpoint - wrist| over frames with the hand seen;
                             ///< hand_to_forearm * forearm when the hand was never seen
  double scale_m = 0.0;      ///< d_h = upper_arm + forearm + hand (0 when no frame was valid)
  int n_arm_frames = 0;      ///< frames with a valid torso and arm
  int n_hand_frames = 0;     ///< of those, frames with the hand seen
};

/// Medians of the arm's link lengths over `frames` (human_kinematics.hpp defines the points).
/// `config.scale_m` and `config.hand_length_m` are ignored here.
HumanArmLengths estimateHumanArmLengths(const Skeleton& frames, const HumanKinematicsConfig& config = {});

/// `config` with scale_m and hand_length_m set from `lengths` (unchanged when no frame was valid).
HumanKinematicsConfig withDemoScale(HumanKinematicsConfig config, const HumanArmLengths& lengths);

}  // namespace nao
