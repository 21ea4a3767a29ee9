// The simulated NAO arm: an ODE world built from the ArmModel, driven by position servos.
//
// Physics: torso fixed to the world (world frame = torso frame, gravity -z), one ODE body per
// link placed at its centre of mass with the URDF inertia, one hinge per joint with the URDF
// axis. Hinge stops sit 1 degree outside the URDF limits as a safety net (see kStopMarginRad
// in sim_arm.cpp); the servo itself keeps every joint inside the limits. Integrated with
// dWorldStep, the direct solver: no random constraint reordering, so runs repeat bitwise.
//
// Servo law at every physics substep (1 ms), standing in for NAO's position servos:
//   e = q_cmd - q,   v* = sign(e) * min(K |e|, v_max, sqrt(a_brake |e|)),
//   v = v* limited to change by at most a_brake * dt per substep,
// sent as the hinge motor's target velocity, motor torque capped at the URDF effort.
//  - K (servo_gain_per_s, default 25 /s): 40 ms time constant close to the target.
//  - v_max: the URDF velocity limit.
//  - a_brake: a deceleration the motor can always deliver, per joint, from the URDF at
//    configure time: half of (effort - worst-case gravity torque) / worst-case inertia.
//  - The slew limit gives an acceleration-limited profile (accelerate, cruise, brake), so
//    distal joints never jerk hard enough to overpower the shoulder motors by reaction.
//  - The square-root term brakes at a_brake / 2, which the slew limit can always follow,
//    so large steps stop on the target instead of overshooting it.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/kinematics.hpp"
#include "nao/robot_backend.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>

// Opaque ODE handles (ode/common.h), declared here so users of this header need not include ODE.
struct dxWorld;
struct dxBody;
struct dxJoint;

namespace nao {

struct SimParams {
  double dt_s = 1e-3;               ///< physics step, s
  int substeps_per_tick = 100;      ///< physics steps per control tick (100 x 1 ms = 10 Hz)
  double servo_gain_per_s = 25.0;   ///< K of the servo law, 1/s
  double gravity_mps2 = 9.81;       ///< magnitude, along -z of the torso frame
  int warmup_substeps = 10;         ///< steps taken in configure so ODE sizes its arena there
};

/// The gain that inverts the servo law's first-order part over one control tick: a first-order
/// servo covers 1 − exp(−K T) of a step in T, so a command g·e ahead, g = 1 / (1 − exp(−K T)),
/// ends the tick on target (1.0894 for K 25 /s, T 0.1 s). The expert's first step and the
/// reference policy's residual base; the slew and braking limits are what it leaves out.
inline double servoStepGain(const SimParams& p) {
  return 1.0 / (1.0 - std::exp(-p.servo_gain_per_s * (p.dt_s * p.substeps_per_tick)));
}

/// The servo's velocity target for the error e = q_cmd − q before the slew limit, rad/s:
/// sign(e) · min(K |e|, v_max, √(a_brake |e|)). Real-time safe.
double servoTargetVelocity(double error, double gain, double v_max, double a_brake);

/// The servo law of one physics substep (the header's): servoTargetVelocity, changed by at most
/// a_brake · dt from the previous substep's v_prev, rad/s. stepSim sends it to the hinge motor;
/// the trainer's copy of the arm (toolchain arm_copy.hpp) integrates it. Real-time safe.
double servoVelocity(double error, double v_prev, double gain, double v_max, double a_brake, double dt);

/// Immutable description of the simulation: the arm, the parameters, and per-joint servo
/// braking limits derived from them.
struct SimModel {
  ArmModel arm;
  SimParams params;
  JointVector a_brake;  ///< guaranteed deceleration per joint, rad/s^2
};

/// Builds the SimModel (configure time). Throws std::invalid_argument for parameters out of
/// range and ArmModelError for an arm whose motors cannot hold it against gravity.
SimModel makeSimModel(const ArmModel& arm, const SimParams& params = {});

/// The running simulation: the ODE world and what the last tick measured. Owns its ODE
/// objects; construct and destroy it on the control thread (ODE keeps per-thread data).
class SimData {
 public:
  /// Builds the world with the arm at rest at q0 (clamped to the limits), then takes
  /// `warmup_substeps` steps and resets, so later ticks allocate nothing. Configure time.
  SimData(const SimModel& model, const JointVector& q0);
  ~SimData();
  SimData(const SimData&) = delete;
  SimData& operator=(const SimData&) = delete;

  JointVector q = JointVector::Zero();        ///< joint angles after the last tick, rad
  JointVector qd = JointVector::Zero();       ///< joint velocities after the last tick, rad/s
  JointVector qd_peak = JointVector::Zero();  ///< largest |qd| seen at any substep of the last tick
  JointVector q_cmd = JointVector::Zero();    ///< last command, clamped to the limits, rad
  JointVector v_servo = JointVector::Zero();  ///< motor target velocities of the last substep, rad/s
  std::int64_t substeps = 0;                  ///< physics steps taken since the last reset

  dxWorld* world = nullptr;
  std::array<dxBody*, kNumJoints> body{};    ///< body of the link moved by joint j
  std::array<dxJoint*, kNumJoints> hinge{};  ///< hinge of joint j
  ArmData kin;                               ///< workspace for placing bodies
};

/// Puts the arm at rest at pose q0 (clamped to limits) and commands it to stay there.
/// Real-time safe (moves existing bodies only).
void resetSim(const SimModel& model, SimData& data, const JointVector& q0);

/// Advances one control tick: `substeps_per_tick` physics steps toward q_cmd (clamped to the
/// limits). Updates q, qd, qd_peak, q_cmd in `data`; returns data.q. Real-time safe after
/// the SimData constructor's warm-up: no allocation, no I/O.
const JointVector& stepSim(const SimModel& model, SimData& data, const JointVector& q_cmd);

/// The whole dynamic state of a SimData: every body's pose and velocities plus the servo's
/// memory. restoreSim of a snapshot continues the run from that instant (the offline expert of
/// the policy's training labels tries commands from one state: toolchain policy_dataset).
struct SimSnapshot {
  std::array<std::array<double, 13>, kNumJoints> body{};  ///< position 3, quaternion 4, linear 3, angular 3
  JointVector q = JointVector::Zero(), qd = JointVector::Zero(), qd_peak = JointVector::Zero();
  JointVector q_cmd = JointVector::Zero(), v_servo = JointVector::Zero();
  std::int64_t substeps = 0;
};

/// Copies the state of `data` into `out`. Real-time safe.
void captureSim(const SimData& data, SimSnapshot& out);
/// Puts `data` in the state of `snap` (taken from a SimData of the same model). Real-time safe.
void restoreSim(SimData& data, const SimSnapshot& snap);

/// Caps each joint motor's torque at scale[j] x its URDF effort (NAO's stiffness is such a
/// fraction of the motor's maximum current; nao_lola_sim uses it). The default, set by the
/// SimData constructor, is 1 for every joint; nao_rt's in-process arm never calls this.
/// scale is clamped to [0, 1]. Real-time safe.
void setSimTorqueScale(const SimModel& model, SimData& data, const JointVector& scale);

/// Hand point of the simulated arm in the torso frame, from the ODE body pose of the wrist
/// link (not from the joint angles: an independent check of the kinematics). Real-time safe.
Eigen::Vector3d simHandPosition(const SimModel& model, const SimData& data);

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

/// The simulated arm's physics steps must make up exactly one control period (the ODE backend
/// runs SimParams::substeps_per_tick steps per command). Throws std::invalid_argument.
inline void checkSimPeriod(const SimParams& sim, double period_s) {
  if (std::abs(sim.dt_s * sim.substeps_per_tick - period_s) > 1e-9)
    throw std::invalid_argument("controller: physics substeps do not add up to the control period");
}

}  // namespace nao
