// The command limiter and a tick's command (nao/rollout.hpp).
#include "nao/rollout.hpp"

#include <algorithm>
#include <utility>

namespace nao {

void commandBounds(const ArmModel& arm, double period_s, const JointVector& q, JointVector& lo, JointVector& hi) {
  for (int j = 0; j < kNumJoints; ++j) {
    const double step = arm.v_max[j] * period_s;
    lo[j] = std::max(arm.q_min[j], q[j] - step);
    hi[j] = std::min(arm.q_max[j], q[j] + step);
    if (lo[j] > hi[j]) std::swap(lo[j], hi[j]);
  }
}

std::uint32_t limitCommand(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                           JointVector& q_cmd, const JointEnvelope* envelope) {
  std::uint32_t flags = 0;
  // A NaN would pass std::clamp unchanged: hold instead.
  if (!a.allFinite()) {
    flags |= kCommandNonFinite;
    q_cmd = q;
  } else {
    q_cmd = q + a;
  }
  JointVector lo, hi;
  commandBounds(arm, period_s, q, lo, hi);
  for (int j = 0; j < kNumJoints; ++j) {
    const double c = std::clamp(q_cmd[j], lo[j], hi[j]);
    if (c != q_cmd[j]) flags |= kCommandClamped;
    q_cmd[j] = c;
    if (envelope == nullptr) continue;
    // Inside the envelope where the reach allows; else the end of the reach nearest to it.
    const double e = std::clamp(c, std::max(lo[j], std::min(envelope->lo[j], hi[j])),
                                std::min(hi[j], std::max(envelope->hi[j], lo[j])));
    if (e != c) flags |= kCommandEnveloped;
    q_cmd[j] = e;
  }
  return flags;
}

JointVector limitCommand(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                         bool& limited) {
  JointVector q_cmd;
  limited = limitCommand(arm, period_s, q, a, q_cmd) != 0;
  return q_cmd;
}

CommandStep commandFor(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                       const JointEnvelope* envelope) {
  CommandStep step;
  step.q = q;
  step.limit = limitCommand(arm, period_s, q, a, step.q_cmd, envelope);
  // A non-finite action was held (a = 0): that is the action the tick took.
  if (step.limit & kCommandNonFinite)
    step.a.setZero();
  else
    step.a = a;
  step.a_applied = step.q_cmd - step.q;
  return step;
}

}  // namespace nao
