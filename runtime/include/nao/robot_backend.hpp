// The robot behind the controller (DESIGN §9, STYLE 18): one small interface in the style of
// ros2_control's SystemInterface. The controller never knows which robot it drives:
//  - OdeArmBackend: the in-process ODE arm (default; deterministic, bit for bit);
//  - LolaBackend (lola_backend.hpp): a NAO V6 through LoLA, its low-level socket protocol.
//
// Lifecycle: a backend is built at configure time (everything that allocates or opens a
// socket); activate -> command x N -> deactivate, all real-time safe (no allocation, no
// exception). In-loop anomalies are fault bits (ControllerFault, bits 8 and up), never throws.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/sim_arm.hpp"

#include <cstdint>
#include <memory>

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

/// The in-process ODE arm as a backend: one command is one stepSim (SimParams::substeps_per_tick
/// physics steps). Either it owns its simulation (nao_rt --robot ode: the backend is the
/// hardware, nothing else holds an ODE world) or it drives one its caller owns (the toolchain's
/// rollouts, which snapshot and restore the SimData between ticks).
class OdeArmBackend final : public RobotBackend {
 public:
  /// Drives `data` of `model`, both owned by the caller, which must outlive the backend.
  OdeArmBackend(const SimModel& model, SimData& data) : model_(model), data_(data) {}
  /// Builds and owns the simulation of `arm` (makeSimModel(arm, params)), at rest at q0 (SimData's
  /// constructor: configure time, allocates; throws like makeSimModel).
  OdeArmBackend(const ArmModel& arm, const SimParams& params, const JointVector& q0)
      : own_model_(std::make_unique<SimModel>(makeSimModel(arm, params))),
        own_data_(std::make_unique<SimData>(*own_model_, q0)),
        model_(*own_model_),
        data_(*own_data_) {}

  const JointVector& activate(const JointVector& q0) override {
    resetSim(model_, data_, q0);
    q0_ = q0;
    return q0_;
  }
  const JointVector& measured() const override { return data_.q; }
  const JointVector& command(const JointVector& q_cmd) override { return stepSim(model_, data_, q_cmd); }
  std::uint32_t faults() const override { return 0; }
  std::int64_t waitNs() const override { return 0; }
  RobotStop stopReason() const override { return RobotStop::kNone; }
  void deactivate() override { data_.q_cmd = data_.q; }

  const SimModel& model() const { return model_; }
  const SimData& data() const { return data_; }

 private:
  std::unique_ptr<SimModel> own_model_;  ///< set when the backend owns its simulation
  std::unique_ptr<SimData> own_data_;
  const SimModel& model_;
  SimData& data_;
  JointVector q0_ = JointVector::Zero();  ///< the pose activate placed the arm at
};

}  // namespace nao
