// A policy's own runs labelled by the expert of the executed demonstrations (docs/autonomous.md
// "DAgger"): the states a policy reaches itself, each with the command the expert would give
// there. Offline code: allocates, may throw.
#pragma once

#include "nao/rollout.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/policy_dataset.hpp"

#include <vector>

namespace nao::tools {

/// `policy`'s run of `movement` on the simulated arm `sim` (any state; reset here) from rest at
/// `start` for `ticks` ticks, its actions applied as the controller applies them (rolloutPolicy:
/// a non-finite action is 0, q + a limited to the position limits, one period's reach and
/// `workspace` when not null), and every tick labelled as executeDemos labels an executed
/// demonstration: the expert's command within the controller's bounds that ends the tick at
/// f(t+1) (clamped, f held at its last sample past its end). With `phase_window` > 0 the target
/// is instead f(φ+1), φ the run's phase: at each tick the sample nearest to q(t) (joint space)
/// among φ(t−1) .. φ(t−1) + phase_window, φ(−1) = 0, so a run that fell behind or went ahead is
/// asked to continue the demonstration from where it is, not to jump to tick t's pose. The
/// sequence holds the states the policy reached: q(t), the applied a(t−1), r = target − q(t) and
/// the label a(t) = c*(t) − q(t); worst_miss_rad is the expert's largest miss. demo and rollout
/// are left for the caller.
PolicySequence executeLabelled(const SimModel& sim_model, SimData& sim, const std::vector<JointVector>& f,
                               const JointVector& start, int ticks, int movement, const RolloutPolicy& policy,
                               const JointEnvelope* workspace, const ExecutionOptions& options, int phase_window = 0);

}  // namespace nao::tools
