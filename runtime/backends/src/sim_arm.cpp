#include "nao/sim_arm.hpp"

#include <Eigen/Eigenvalues>
#include <ode/ode.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <stdexcept>
#include <string>

namespace nao {
namespace {

// ODE's hinge stops sit this far outside the URDF limits. When a powered hinge rests on a
// stop, ODE cannot solve motor and stop together and applies the motor's full torque as an
// impulse instead (its "fudge factor" approximation), which kicks the whole chain. The servo
// targets are clamped to the URDF limits and never overshoot, so the stops are only a
// safety net against external pushes and are never touched in normal motion.
constexpr double kStopMarginRad = 1.0 * 3.14159265358979323846 / 180.0;

void initOdeOnce() {
  static std::once_flag flag;
  std::call_once(flag, [] {
    if (!dInitODE2(0)) throw std::runtime_error("ODE: dInitODE2 failed");
  });
  // Per-thread ODE data; cheap and idempotent when already allocated for this thread.
  if (!dAllocateODEDataForThread(dAllocateMaskAll))
    throw std::runtime_error("ODE: dAllocateODEDataForThread failed");
}

void setBodyPose(dBodyID body, const Eigen::Matrix3d& R_TL, const Eigen::Vector3d& p_TL,
                 const Eigen::Vector3d& p_LC) {
  const Eigen::Vector3d p_TC = p_TL + R_TL * p_LC;
  dMatrix3 R;  // ODE: row-major 3x4
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R[4 * r + c] = R_TL(r, c);
    R[4 * r + 3] = 0.0;
  }
  dBodySetPosition(body, p_TC.x(), p_TC.y(), p_TC.z());
  dBodySetRotation(body, R);
  dBodySetLinearVel(body, 0, 0, 0);
  dBodySetAngularVel(body, 0, 0, 0);
}

// Conservative deceleration each joint's motor can always produce: whatever the pose, the
// links it moves are no farther from its axis than the summed link offsets, which bounds
// both the inertia it drives and the gravity torque it must hold.
JointVector brakingLimits(const ArmModel& arm, double g) {
  JointVector a;
  for (int j = 0; j < kNumJoints; ++j) {
    double inertia = 0.0, gravity_torque = 0.0, reach = 0.0;
    for (int i = j; i < kNumJoints; ++i) {
      if (i > j) reach += arm.p_PJ[i].norm();
      const LinkInertial& L = arm.link[i];
      const double r = reach + L.p_LC.norm();
      const double lambda_max = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(L.I_C).eigenvalues().maxCoeff();
      inertia += L.mass * r * r + lambda_max;
      gravity_torque += L.mass * g * r;
    }
    const double spare = arm.tau_max[j] - gravity_torque;
    if (!(spare > 0.0))
      throw ArmModelError(std::string("joint '") + kJointNames[j] + "': effort limit " +
                          std::to_string(arm.tau_max[j]) + " N m cannot hold the arm against gravity (up to " +
                          std::to_string(gravity_torque) + " N m)");
    a[j] = 0.5 * spare / inertia;
  }
  return a;
}

}  // namespace

// The servo law of the header. The square-root term brakes along a curve planned at a_brake / 2:
// the slew limit (a_brake) can then always follow it, so the joint stops on the target instead of
// a step late.
double servoTargetVelocity(double error, double gain, double v_max, double a_brake) {
  const double e = std::abs(error);
  const double speed = std::min({gain * e, v_max, std::sqrt(a_brake * e)});
  return error < 0.0 ? -speed : speed;
}

// The slew limit: the target velocity changes by at most a_brake * dt per step, so no joint is
// asked for more acceleration than its motor can give and the reaction torques on the proximal
// joints stay within their efforts.
double servoVelocity(double error, double v_prev, double gain, double v_max, double a_brake, double dt) {
  const double v = servoTargetVelocity(error, gain, v_max, a_brake);
  const double dv = a_brake * dt;
  return std::min(std::max(v, v_prev - dv), v_prev + dv);
}

SimModel makeSimModel(const ArmModel& arm, const SimParams& params) {
  if (!(params.dt_s > 0.0 && params.dt_s <= 0.01))
    throw std::invalid_argument("simulation: dt_s must be in (0, 0.01] s, got " + std::to_string(params.dt_s));
  if (params.substeps_per_tick < 1)
    throw std::invalid_argument("simulation: substeps_per_tick must be >= 1");
  if (!(params.servo_gain_per_s > 0.0) || params.servo_gain_per_s * params.dt_s >= 1.0)
    throw std::invalid_argument("simulation: servo_gain_per_s must be > 0 and below 1/dt_s");
  if (!(params.gravity_mps2 >= 0.0)) throw std::invalid_argument("simulation: gravity_mps2 must be >= 0");
  if (params.warmup_substeps < 1) throw std::invalid_argument("simulation: warmup_substeps must be >= 1");
  SimModel model;
  model.arm = arm;
  model.params = params;
  model.a_brake = brakingLimits(arm, params.gravity_mps2);
  return model;
}

SimData::SimData(const SimModel& model, const JointVector& q0) {
  initOdeOnce();
  const ArmModel& arm = model.arm;
  world = dWorldCreate();
  dWorldSetGravity(world, 0, 0, -model.params.gravity_mps2);

  // Build at the zero pose: ODE takes a hinge's zero angle from the bodies' poses at the
  // moment its axis is set, so zero must be the URDF zero.
  forwardKinematics(arm, kin, JointVector::Zero());
  for (int j = 0; j < kNumJoints; ++j) {
    const LinkInertial& L = arm.link[j];
    body[j] = dBodyCreate(world);
    dMass m;
    // Inertia about the CoM in link axes; the body frame is the link frame moved to the CoM.
    dMassSetParameters(&m, L.mass, 0, 0, 0, L.I_C(0, 0), L.I_C(1, 1), L.I_C(2, 2), L.I_C(0, 1), L.I_C(0, 2),
                       L.I_C(1, 2));
    dBodySetMass(body[j], &m);
    setBodyPose(body[j], kin.R_TJ[j], kin.p_TJ[j], L.p_LC);
  }
  for (int j = 0; j < kNumJoints; ++j) {
    hinge[j] = dJointCreateHinge(world, nullptr);
    // (child, parent): the angle is the child's rotation about the axis, as in the URDF.
    // Joint 0's parent is the torso, which is the static world.
    dJointAttach(hinge[j], body[j], j == 0 ? nullptr : body[j - 1]);
    dJointSetHingeAnchor(hinge[j], kin.p_TJ[j].x(), kin.p_TJ[j].y(), kin.p_TJ[j].z());
    dJointSetHingeAxis(hinge[j], kin.a_TJ[j].x(), kin.a_TJ[j].y(), kin.a_TJ[j].z());
    dJointSetHingeParam(hinge[j], dParamLoStop, arm.q_min[j] - kStopMarginRad);
    dJointSetHingeParam(hinge[j], dParamHiStop, arm.q_max[j] + kStopMarginRad);
    dJointSetHingeParam(hinge[j], dParamFMax, arm.tau_max[j]);
    dJointSetHingeParam(hinge[j], dParamVel, 0.0);
  }

  // Warm-up: the first dWorldStep sizes ODE's step arena; do it here, not in the loop.
  resetSim(model, *this, q0);
  for (int s = 0; s < model.params.warmup_substeps; ++s) dWorldStep(world, model.params.dt_s);
  resetSim(model, *this, q0);
}

SimData::~SimData() {
  if (world) dWorldDestroy(world);  // also destroys its bodies and joints
}

void resetSim(const SimModel& model, SimData& data, const JointVector& q0) {
  const ArmModel& arm = model.arm;
  const JointVector q = clampToLimits(arm, q0);
  forwardKinematics(arm, data.kin, q);
  for (int j = 0; j < kNumJoints; ++j) {
    setBodyPose(data.body[j], data.kin.R_TJ[j], data.kin.p_TJ[j], arm.link[j].p_LC);
    dJointSetHingeParam(data.hinge[j], dParamVel, 0.0);
  }
  for (int j = 0; j < kNumJoints; ++j) data.q[j] = dJointGetHingeAngle(data.hinge[j]);
  data.qd.setZero();
  data.qd_peak.setZero();
  data.v_servo.setZero();
  data.q_cmd = q;
  data.substeps = 0;
}

const JointVector& stepSim(const SimModel& model, SimData& data, const JointVector& q_cmd) {
  const ArmModel& arm = model.arm;
  const SimParams& p = model.params;
  data.q_cmd = clampToLimits(arm, q_cmd);
  data.qd_peak.setZero();
  for (int s = 0; s < p.substeps_per_tick; ++s) {
    for (int j = 0; j < kNumJoints; ++j) {
      const double e = data.q_cmd[j] - dJointGetHingeAngle(data.hinge[j]);
      data.v_servo[j] = servoVelocity(e, data.v_servo[j], p.servo_gain_per_s, arm.v_max[j], model.a_brake[j], p.dt_s);
      dJointSetHingeParam(data.hinge[j], dParamVel, data.v_servo[j]);
    }
    dWorldStep(data.world, p.dt_s);
    ++data.substeps;
    for (int j = 0; j < kNumJoints; ++j)
      data.qd_peak[j] = std::max(data.qd_peak[j], std::abs(dJointGetHingeAngleRate(data.hinge[j])));
  }
  for (int j = 0; j < kNumJoints; ++j) {
    data.q[j] = dJointGetHingeAngle(data.hinge[j]);
    data.qd[j] = dJointGetHingeAngleRate(data.hinge[j]);
  }
  return data.q;
}

void captureSim(const SimData& data, SimSnapshot& out) {
  for (int j = 0; j < kNumJoints; ++j) {
    std::array<double, 13>& b = out.body[static_cast<std::size_t>(j)];
    const dReal* p = dBodyGetPosition(data.body[j]);
    const dReal* q = dBodyGetQuaternion(data.body[j]);
    const dReal* v = dBodyGetLinearVel(data.body[j]);
    const dReal* w = dBodyGetAngularVel(data.body[j]);
    for (int k = 0; k < 3; ++k) b[static_cast<std::size_t>(k)] = p[k];
    for (int k = 0; k < 4; ++k) b[static_cast<std::size_t>(3 + k)] = q[k];
    for (int k = 0; k < 3; ++k) b[static_cast<std::size_t>(7 + k)] = v[k];
    for (int k = 0; k < 3; ++k) b[static_cast<std::size_t>(10 + k)] = w[k];
  }
  out.q = data.q;
  out.qd = data.qd;
  out.qd_peak = data.qd_peak;
  out.q_cmd = data.q_cmd;
  out.v_servo = data.v_servo;
  out.substeps = data.substeps;
}

void restoreSim(SimData& data, const SimSnapshot& snap) {
  for (int j = 0; j < kNumJoints; ++j) {
    const std::array<double, 13>& b = snap.body[static_cast<std::size_t>(j)];
    dBodySetPosition(data.body[j], b[0], b[1], b[2]);
    const dQuaternion q = {b[3], b[4], b[5], b[6]};
    dBodySetQuaternion(data.body[j], q);
    dBodySetLinearVel(data.body[j], b[7], b[8], b[9]);
    dBodySetAngularVel(data.body[j], b[10], b[11], b[12]);
    dJointSetHingeParam(data.hinge[j], dParamVel, snap.v_servo[j]);
  }
  data.q = snap.q;
  data.qd = snap.qd;
  data.qd_peak = snap.qd_peak;
  data.q_cmd = snap.q_cmd;
  data.v_servo = snap.v_servo;
  data.substeps = snap.substeps;
}

void setSimTorqueScale(const SimModel& model, SimData& data, const JointVector& scale) {
  for (int j = 0; j < kNumJoints; ++j)
    dJointSetHingeParam(data.hinge[j], dParamFMax, model.arm.tau_max[j] * std::clamp(scale[j], 0.0, 1.0));
}

Eigen::Vector3d simHandPosition(const SimModel& model, const SimData& data) {
  constexpr int w = kNumJoints - 1;
  const dReal* p = dBodyGetPosition(data.body[w]);
  const dReal* R = dBodyGetRotation(data.body[w]);
  Eigen::Matrix3d R_TW;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R_TW(r, c) = R[4 * r + c];
  const Eigen::Vector3d p_TC(p[0], p[1], p[2]);
  // Body origin is the wrist link's CoM; step back to the wrist frame, then out to the hand.
  return p_TC + R_TW * (model.arm.p_WH - model.arm.link[w].p_LC);
}

}  // namespace nao
