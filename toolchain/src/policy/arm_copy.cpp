// The trainer's copy of the simulated arm (nao/tools/arm_copy.hpp).
#include "nao/tools/arm_copy.hpp"

#include "nao/rollout.hpp"

#include <algorithm>
#include <cmath>

namespace nao::tools {
namespace {

// ∂v/∂e of servoTargetVelocity where its smallest term is taken (std::min's first of equals):
// K |e| gives K, v_max gives 0, √(a |e|) gives ½ √(a / |e|). At e = 0 the first term is taken.
double targetVelocitySlope(double error, double gain, double v_max, double a_brake) {
  const double e = std::abs(error);
  const double linear = gain * e, root = std::sqrt(a_brake * e);
  if (linear <= v_max && linear <= root) return gain;
  if (v_max <= root) return 0.0;
  return 0.5 * std::sqrt(a_brake / e);
}

}  // namespace

void stepArmCopy(const SimModel& sim, ArmCopyState& s, const JointVector& q_cmd, ArmCopyJacobian* jac) {
  const SimParams& p = sim.params;
  const JointVector c = clampToLimits(sim.arm, q_cmd);
  for (int j = 0; j < kNumJoints; ++j) {
    const double gain = p.servo_gain_per_s, v_max = sim.arm.v_max[j], a_brake = sim.a_brake[j], dt = p.dt_s;
    double q = s.q[j], v = s.v[j];
    // Forward-mode derivatives of q and v with respect to (q0, v0, c).
    Eigen::RowVector3d dq(1.0, 0.0, 0.0), dv(0.0, 1.0, 0.0);
    const Eigen::RowVector3d dc(0.0, 0.0, c[j] == q_cmd[j] ? 1.0 : 0.0);
    for (int k = 0; k < p.substeps_per_tick; ++k) {
      const double e = c[j] - q;
      const double v_next = servoVelocity(e, v, gain, v_max, a_brake, dt);
      if (jac != nullptr) {
        // The slew limit either lets the target through or holds v within a_brake·dt of v.
        if (v_next == servoTargetVelocity(e, gain, v_max, a_brake))
          dv = targetVelocitySlope(e, gain, v_max, a_brake) * (dc - dq);
        dq += dt * dv;
      }
      v = v_next;
      q += v * dt;
    }
    s.q[j] = q;
    s.v[j] = v;
    if (jac != nullptr) {
      jac->d[static_cast<std::size_t>(j)].row(0) = dq;
      jac->d[static_cast<std::size_t>(j)].row(1) = dv;
    }
  }
}

CommandDerivative commandDerivative(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                                    const JointVector& q_cmd) {
  CommandDerivative d;
  // A non-finite action is taken as 0: the command is q itself where nothing cuts it.
  const bool finite = a.allFinite();
  for (int j = 0; j < kNumJoints; ++j) {
    const double step = arm.v_max[j] * period_s;
    if (q_cmd[j] == (finite ? q[j] + a[j] : q[j])) {
      d.d_q[j] = 1.0;
      d.d_a[j] = finite ? 1.0 : 0.0;
    } else if (q_cmd[j] == q[j] - step || q_cmd[j] == q[j] + step) {
      d.d_q[j] = 1.0;  // one period's reach from q
    }
  }
  return d;
}

}  // namespace nao::tools
