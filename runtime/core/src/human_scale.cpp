// The human scale of a whole demonstration (nao/human_scale.hpp).
#include "nao/human_scale.hpp"

#include "nao/median.hpp"

#include <vector>

namespace nao {

HumanArmLengths estimateHumanArmLengths(const Skeleton& frames, const HumanKinematicsConfig& config) {
  HumanKinematicsConfig per_frame = config;
  per_frame.scale_m = 0.0;
  per_frame.hand_length_m = 0.0;
  HumanArmData data;
  std::vector<double> upper, fore, hand;
  for (const SkeletonFrame& f : frames) {
    humanArmKinematics(per_frame, data, f);
    if (!data.valid) continue;
    upper.push_back(data.l_upper_m);
    fore.push_back(data.l_forearm_m);
    if (data.hand_seen) hand.push_back(data.l_hand_m);
  }
  HumanArmLengths out;
  out.n_arm_frames = static_cast<int>(upper.size());
  out.n_hand_frames = static_cast<int>(hand.size());
  if (upper.empty()) return out;
  out.upper_arm_m = median(upper);
  out.forearm_m = median(fore);
  out.hand_m = hand.empty() ? config.hand_to_forearm * out.forearm_m : median(hand);
  out.scale_m = out.upper_arm_m + out.forearm_m + out.hand_m;
  return out;
}

HumanKinematicsConfig withDemoScale(HumanKinematicsConfig config, const HumanArmLengths& lengths) {
  if (lengths.scale_m > 0.0) {
    config.scale_m = lengths.scale_m;
    config.hand_length_m = lengths.hand_m;
  }
  return config;
}

}  // namespace nao
