// The robot behind the controller: one small interface in the style of
// ros2_control's SystemInterface. The controller never knows which robot it drives:
//  - OdeArmBackend (sim_arm.hpp, nao_backends): the in-process ODE arm (default; deterministic,
//    bit for bit);
//  - LolaBackend (lola_backend.hpp, nao_backends): a NAO V6 through LoLA, its low-level socket
//    protocol;
//  - a robot framework's own arm (examples/embed: a kinematic arm of a few lines).
//
// Lifecycle: a backend is built at configure time (everything that allocates or opens a
// socket); activate -> command x N -> deactivate, all real-time safe (no allocation, no
// exception). In-loop anomalies are fault bits (ControllerFault, bits 8 and up), never throws.
#pragma once

#include "nao/arm_model.hpp"

#include <cstdint>

namespace nao {

/// Counts the heap allocations of the thread that calls start() until stop() (nao_rt backs it
/// with its counting allocator; the allocation tests with theirs). A backend with a thread of
/// its own is given one for that thread.
struct AllocationProbe {
  virtual ~AllocationProbe() = default;
  virtual void start() = 0;
  virtual std::int64_t stop() = 0;
  /// A probe for one more thread (a backend's own), or nullptr if allocations are counted on
  /// the calling thread only.
  virtual AllocationProbe* companion() { return nullptr; }
};

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
};

}  // namespace nao
