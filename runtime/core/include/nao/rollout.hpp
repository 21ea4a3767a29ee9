// The command path of a tick: what every tick of every rollout does between an action and the
// command sent to the arm, written once. The controller's tick calls commandFor once per tick;
// the toolchain's rollouts (training data execution, selection runs, evaluation baselines)
// call the same function with their own action laws, through nao_backends' rolloutStep, so a
// baseline never re-spells the controller.
//
//   q_cmd = limitCommand(q, a):   q + a inside the position limits and inside what the servos
//                                 can reach in one period (v_max · T); a non-finite action holds
//   commandFor(q, a):             limitCommand, and what it applied: the action as taken (0 when
//                                 non-finite) and q_cmd − q, the next tick's a(t−1)
//
// All real-time safe: no allocation, no exception, no I/O, no robot.
#pragma once

#include "nao/arm_model.hpp"

#include <cstdint>
#include <limits>

namespace nao {

/// What limitCommand changed (bits).
enum CommandLimitFlags : std::uint32_t {
  kCommandClamped = 1u << 0,    ///< a joint was cut to its position limit or to one period's reach
  kCommandNonFinite = 1u << 1,  ///< the action had a NaN/Inf: replaced by 0 (hold where the arm is)
  kCommandEnveloped = 1u << 2,  ///< a joint was cut to the workspace envelope
};

/// A joint-space box the commands stay in besides the arm's own limits, rad: an autonomous
/// run's demonstrated workspace (the controller's, from the model's key poses). The default
/// box is everything: the arm's limits alone.
struct JointEnvelope {
  JointVector lo = JointVector::Constant(-std::numeric_limits<double>::infinity());
  JointVector hi = JointVector::Constant(std::numeric_limits<double>::infinity());
};

/// The box lo..hi widened by margin_rad on every side (an autonomous model's demonstrated joint
/// range, the controller's workspace envelope). Real-time safe.
inline JointEnvelope widenedEnvelope(const JointVector& lo, const JointVector& hi, double margin_rad) {
  JointEnvelope e;
  e.lo = lo.array() - margin_rad;
  e.hi = hi.array() + margin_rad;
  return e;
}

/// The command interval of joint j at q: [lo_j, hi_j] = [q_min_j, q_max_j] ∩ [q_j − v_max_j T,
/// q_j + v_max_j T] (T = period_s; the ends swapped when the arm is outside its limits by more
/// than a period's reach, so the interval pulls it back). Rad.
void commandBounds(const ArmModel& arm, double period_s, const JointVector& q, JointVector& lo, JointVector& hi);

/// q + a clamped into commandBounds(q), written to q_cmd (rad). A non-finite a (any joint) is
/// taken as a = 0: the arm holds (still inside the bounds). With an envelope the command is also
/// kept inside it, within one period's reach: an arm outside the envelope is moved back toward
/// it as fast as the servos allow. Returns CommandLimitFlags.
std::uint32_t limitCommand(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                           JointVector& q_cmd, const JointEnvelope* envelope = nullptr);

/// The same, returning q_cmd; `limited` is true when the command differs from q + a.
JointVector limitCommand(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                         bool& limited);

/// What one tick's command is: the limited command and the action as applied.
struct CommandStep {
  JointVector q = JointVector::Zero();          ///< measured angles the command starts from, rad
  JointVector a = JointVector::Zero();          ///< the action as taken: the law's, 0 where it had a NaN/Inf
  JointVector q_cmd = JointVector::Zero();      ///< the command to send (limitCommand), rad
  JointVector a_applied = JointVector::Zero();  ///< q_cmd − q: the action as applied (the next a(t−1))
  std::uint32_t limit = 0;                      ///< CommandLimitFlags
};

/// The command of a tick at the measured angles q for the action a: limitCommand(q, a) within
/// the envelope (if any), the action as taken and as applied. Used by the controller's tick and
/// by every rollout of the toolchain.
CommandStep commandFor(const ArmModel& arm, double period_s, const JointVector& q, const JointVector& a,
                       const JointEnvelope* envelope = nullptr);

}  // namespace nao
