// The arm copy (nao/tools/arm_copy.hpp) as one differentiable step of a batch of runs, for the
// trainer's closed-loop rollouts (docs/autonomous.md). Offline only (libtorch).
#pragma once

#include "nao/sim_arm.hpp"

#include <torch/torch.h>

namespace nao::tools {

/// The tick's result for B runs, kFloat64.
struct ArmTick {
  torch::Tensor q;          ///< [B,J] measured angles at the end of the tick, rad
  torch::Tensor v;          ///< [B,J] the servo's velocity memory, rad/s
  torch::Tensor a_applied;  ///< [B,J] q_cmd − q: the action as the limiter let it through, rad
  torch::Tensor hand;       ///< [B,3] hand point of q in the torso frame, m
};

/// One control tick of B runs: the runtime's command limiter (limitCommand: position limits, one
/// period's reach, the workspace envelope [env_lo, env_hi] per run, ±inf for none) on q + a, then
/// the arm copy (stepArmCopy), then the hand point (forwardKinematics). Inputs [B,J] (q, v, a:
/// any floating type, cast to double; env_*: double); the values are the ones the same code gives
/// run by run. Backward: through the limiter by its exact derivative (commandDerivative: where it
/// cuts, the action gets no gradient - a training loss adds a penalty on a − a_applied instead),
/// the substeps by the copy's Jacobian and the hand by its Jacobian (handJacobian).
ArmTick armCopyTick(const SimModel& sim, double period_s, const torch::Tensor& q, const torch::Tensor& v,
                    const torch::Tensor& a, const torch::Tensor& env_lo, const torch::Tensor& env_hi);

}  // namespace nao::tools
