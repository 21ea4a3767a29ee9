// The robot behind a run: one small interface in the style of ros2_control's SystemInterface.
// The controller (nao_core) never sees a robot: the loop of robot_loop.hpp reads the arm, calls
// updateController with the measured angles and writes the command back, as a robot framework
// drives its controllers (docs/embedding.md); the toolchain's rollouts step it with rolloutStep.
//  - OdeArmBackend (sim_arm.hpp): the in-process ODE arm (default; deterministic, bit for bit);
//  - LolaBackend (lola_backend.hpp): a NAO V6 through LoLA, its low-level socket protocol;
//  - ArmCopyBackend (the toolchain's differentiable arm copy).
// makeRobotBackend (robot_factory.hpp) builds one from nao_rt's --robot.
//
// Lifecycle: a backend is built at configure time (everything that allocates or opens a
// socket); activate -> command x N -> deactivate, all real-time safe (no allocation, no
// exception). In-loop anomalies are fault bits (ControllerFault, bits 8 and up), never throws.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/rollout.hpp"

#include <cstdint>

namespace nao {

/// Why a backend stopped the run early (RobotBackend::stopReason).
enum class RobotStop : int {
  kNone = 0,     ///< running
  kLinkLost,     ///< the robot's socket closed, or no packet for too long: safe stop done as far as possible
  kSignal,       ///< SIGINT/SIGTERM: safe stop done
};

struct RobotBackend {
  virtual ~RobotBackend() = default;
  /// Brings the arm to start pose q0 (rad, clamped to the limits by the caller) and returns the
  /// pose the arm starts the first tick from. Real-time safe.
  virtual const JointVector& activate(const JointVector& q0) = 0;
  /// The measured joint angles after the last activate/command, rad. Real-time safe.
  virtual const JointVector& measured() const = 0;
  /// Applies q_cmd (rad) for one control period and returns the measured angles at its end.
  /// Real-time safe.
  virtual const JointVector& command(const JointVector& q_cmd) = 0;
  /// ControllerFault bits the robot raised during the last command (0 for the ODE arm).
  virtual std::uint32_t faults() const = 0;
  /// Nanoseconds of the last command spent waiting for the robot (LoLA: for sensor packets), so
  /// the tick's own work can be told apart from the robot's clock. Real-time safe.
  virtual std::int64_t waitNs() const = 0;
  /// Not kNone: the backend cannot go on (the run ends after this tick, exit status non-zero).
  virtual RobotStop stopReason() const = 0;
  /// Ends the run: hold where the arm is (a real robot: then ramp the stiffness to 0).
  virtual void deactivate() = 0;
  /// True when the robot's own clock paces the ticks (command waits for its packets, LoLA): a
  /// run then does not sleep to deadlines of its own.
  virtual bool pacesTicks() const { return false; }
};

/// One control period of a rollout with the caller's own action a (the toolchain's rollouts:
/// training data execution, selection runs, evaluation baselines): read the robot's measured q, the
/// tick's command (commandFor, as the controller's tick makes it), write it for one period.
/// Fills `step` and returns the measured angles at the end of the period (the robot's, valid
/// until its next command). Real-time safe.
const JointVector& rolloutStep(const ArmModel& arm, double period_s, RobotBackend& robot, const JointVector& a,
                               CommandStep& step, const JointEnvelope* envelope = nullptr);

}  // namespace nao
