// A copy of the simulated arm for training in closed loop (docs/autonomous.md): the
// servo law of sim_arm.hpp integrated joint by joint, without the rigid-body dynamics.
//
// The ODE arm's hinges follow their motor's target velocity whenever the torque cap allows it,
// and the servo law is per joint and uncoupled, so the executed arm over one tick is, per joint,
// 100 substeps of
//   v ← servoVelocity(c − q, v),   q ← q + v dt
// from the state (q, v) the last tick left (v: the servo's velocity memory, carried across
// ticks). That matches ODE to float noise on most joints (tests/test_arm_copy.cpp measures it);
// a first- or second-order fit of the servo does not (the slew limit of the shoulders is the size
// of the bars the runs are judged by). The copy also carries its own Jacobian through the
// substeps, per joint ∂(q', v')/∂(q, v, c), which the trainer's autograd function
// (toolchain/src/torch/arm_copy_torch.hpp) backpropagates through. Training-time only: nao_rt
// drives the ODE arm or a NAO. Offline code, no libtorch.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/robot_backend.hpp"
#include "nao/sim_arm.hpp"

#include <Eigen/Core>

#include <array>
#include <vector>

namespace nao::tools {

/// The copy's state between ticks: the measured angles and the servo's velocity memory, rad and
/// rad/s (SimData::q and SimData::v_servo of the ODE arm).
struct ArmCopyState {
  JointVector q = JointVector::Zero();
  JointVector v = JointVector::Zero();
};

/// Per joint j, the derivatives of the tick's end state (q'_j, v'_j) (rows) with respect to its
/// start state and the command sent (q_j, v_j, c_j) (columns).
struct ArmCopyJacobian {
  std::array<Eigen::Matrix<double, 2, 3>, kNumJoints> d;
};

/// One control tick of the copy: q_cmd clamped to the position limits (as stepSim does), then
/// SimParams::substeps_per_tick substeps of the servo law from `s`, which it advances. With `jac`
/// the derivatives of the result; where the limits cut the command, ∂/∂c is 0.
void stepArmCopy(const SimModel& sim, ArmCopyState& s, const JointVector& q_cmd, ArmCopyJacobian* jac = nullptr);

/// Per joint, ∂q_cmd/∂q and ∂q_cmd/∂a of the command limiter's result q_cmd (commandFor(q, a),
/// rollout.hpp): (1, 1) where the command is q + a, (1, 0) where it is cut to one period's reach
/// from q or the action was not finite (the arm holds: q_cmd = q), (0, 0) where it is cut to a
/// position limit or the envelope.
struct CommandDerivative {
  JointVector d_q = JointVector::Zero();
  JointVector d_a = JointVector::Zero();
};
CommandDerivative commandDerivative(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                                    const JointVector& q_cmd);

/// The copy as a robot backend (robot_backend.hpp): rollouts run through it the way they run
/// through the ODE arm (rolloutStep, the command limiter), so a replay through the copy is the
/// same loop as one through ODE.
class ArmCopyBackend final : public RobotBackend {
 public:
  /// `sim` (and `log`, if given) must outlive the backend. With a log, every state the arm is in
  /// (after activate and after each command) is appended to it.
  explicit ArmCopyBackend(const SimModel& sim, std::vector<ArmCopyState>* log = nullptr) : sim_(sim), log_(log) {}
  const JointVector& activate(const JointVector& q0) override {
    state_.q = clampToLimits(sim_.arm, q0);
    state_.v.setZero();
    if (log_ != nullptr) log_->push_back(state_);
    return state_.q;
  }
  const JointVector& measured() const override { return state_.q; }
  const JointVector& command(const JointVector& q_cmd) override {
    stepArmCopy(sim_, state_, q_cmd);
    if (log_ != nullptr) log_->push_back(state_);
    return state_.q;
  }
  std::uint32_t faults() const override { return 0; }
  std::int64_t waitNs() const override { return 0; }
  RobotStop stopReason() const override { return RobotStop::kNone; }
  void deactivate() override {}
  const ArmCopyState& state() const { return state_; }

 private:
  const SimModel& sim_;
  std::vector<ArmCopyState>* log_;
  ArmCopyState state_;
};

}  // namespace nao::tools
