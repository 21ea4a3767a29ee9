#include "nao/tools/retarget_cli.hpp"

namespace nao::tools {

void addRetargetSettingOptions(CLI::App* cmd, RetargetSettingArgs& args) {
  cmd->add_option("--priority", args.priority,
                  "Imitation reference q_r: hand (q_x: reproduce the scaled hand path, compensate with the\n"
                  "joints NAO has) or joints (q_q: reproduce the human's joint angles, hand second)")
      ->check(CLI::IsMember({"hand", "joints"}))
      ->capture_default_str();
  cmd->add_option("--lambda-q", args.lambda_q,
                  "Joint priority's price of moving the hand off x_target: q_q's hand misses x_target by\n"
                  "1/(1+lambda_q) of the clamped human angles' miss (0 = the clamped angles)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  cmd->add_option("--posture-weights", args.posture_weights,
                  "Per-joint weights of the human posture kept in the null space (5 values > 0, comma-separated,\n"
                  "joint order RShoulderPitch, RShoulderRoll, RElbowYaw, RElbowRoll, RWristYaw)")
      ->expected(kNumJoints)
      ->delimiter(',')
      ->check(CLI::Range(1e-6, 1e6))
      ->capture_default_str();
}

RetargetParams applyRetargetSetting(const RetargetSettingArgs& args, RetargetParams params) {
  parseRetargetPriority(args.priority.c_str(), params.priority);
  params.lambda_q = args.lambda_q;
  for (int j = 0; j < kNumJoints; ++j) params.posture_weights[j] = args.posture_weights[static_cast<std::size_t>(j)];
  return params;
}

}  // namespace nao::tools
