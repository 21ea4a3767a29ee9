// The controller on a robot backend: read -> update -> write, the cycle a robot framework runs
// around its controllers (ros2_control: read(), ControllerInterface::update(), write()). nao_rt,
// the evaluation's in-process controller and the toolchain drive the controller through these;
// a framework with its own joint interface writes the same few lines (examples/embed).
#pragma once

#include "nao/controller.hpp"
#include "nao/robot_backend.hpp"

namespace nao {

/// Brings `robot` to the start pose q0 (clamped to the limits) and starts the controller's run
/// from the pose the robot reports (activateController). Real-time safe.
template <class Dims>
void activateOnRobot(const ControllerModel<Dims>& model, ControllerData<Dims>& data, RobotBackend& robot,
                     const JointVector& q0, int movement, ControllerClock& clock) {
  activateController(model, data, robot.activate(clampToLimits(model.arm, q0)), movement, clock);
}

namespace detail {
template <class Dims>
const TickRecord& writeAndFinish(const ControllerModel<Dims>& model, ControllerData<Dims>& data, RobotBackend& robot,
                                 const TickRecord& rec) {
  const JointVector& q_end = robot.command(rec.q_cmd);
  return finishTick(model, data, q_end, robot.faults(), robot.waitNs());
}
}  // namespace detail

/// One tick on a robot: read its measured angles, updateController, write the command for one
/// period, and record what the robot did (finishTick: the measured angles at the end of the
/// period, their hand point, the robot's fault bits, its time without its waiting). Returns
/// data.record. Real-time safe.
template <class Dims>
const TickRecord& runControllerTick(const ControllerModel<Dims>& model, ControllerData<Dims>& data,
                                    RobotBackend& robot, const SkeletonFrame* frame) {
  return detail::writeAndFinish(model, data, robot, updateController(model, data, robot.measured(), frame));
}

/// The same with `law`'s action in place of the policy's (updateController's ActionLaw form).
template <class Dims>
const TickRecord& runControllerTick(const ControllerModel<Dims>& model, ControllerData<Dims>& data,
                                    RobotBackend& robot, const SkeletonFrame* frame, ActionLaw& law) {
  return detail::writeAndFinish(model, data, robot, updateController(model, data, robot.measured(), frame, law));
}

/// Ends the controller's run and has the robot hold where it is (LoLA then ramps the stiffness
/// to 0). Real-time safe.
template <class Dims>
void deactivateOnRobot(const ControllerModel<Dims>& model, ControllerData<Dims>& data, RobotBackend& robot) {
  robot.deactivate();
  deactivateController(model, data);
}

}  // namespace nao
