// The rollout step on a robot backend (nao/robot_backend.hpp).
#include "nao/robot_backend.hpp"

namespace nao {

const JointVector& rolloutStep(const ArmModel& arm, double period_s, RobotBackend& robot, const JointVector& a,
                               CommandStep& step, const JointEnvelope* envelope) {
  step = commandFor(arm, period_s, robot.measured(), a, envelope);
  return robot.command(step.q_cmd);
}

}  // namespace nao
