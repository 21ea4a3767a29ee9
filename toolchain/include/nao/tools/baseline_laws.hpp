// The evaluation's closed-form baselines of a reference-conditioned policy, as action laws that
// act in the runtime's own tick in place of the policy (nao/controller.hpp ActionLaw;
// nao_toolchain evaluate runs them through nao_rt's run in process, docs/evaluate.md). The
// reference, the command limits and the arm are the controller's. Real-time safe. (Not
// linear_ar.hpp's tools::ActionLaw, the rollouts' function of the arm's history.)
#pragma once

#include "nao/controller.hpp"

namespace nao::tools {

/// The key-pose blend law the training labels follow: a = p² a(t−1) + (1 − p)² (r − q), r the
/// snapped key pose.
struct BlendLaw final : nao::ActionLaw {
  explicit BlendLaw(double p) : pole(p) {}
  const char* name() const override { return "blend law"; }
  JointVector action(const ActionInput& in) override {
    return pole * pole * in.a_prev + (1.0 - pole) * (1.0 - pole) * (in.key_pose - in.q);
  }
  double pole;
};

/// The fixed-gain inversion of a first-order servo on the policy's feature-extracted target:
/// a = g (clamp(f(t+1)) − q). g = 1 / (1 − exp(−K T)) inverts the simulated servo (gain K,
/// period T) exactly if it were first order (servoStepGain): the bar for what a policy learns
/// beyond it.
struct GainLaw final : nao::ActionLaw {
  explicit GainLaw(double g) : gain(g) {}
  const char* name() const override { return "gain law"; }
  JointVector action(const ActionInput& in) override { return gain * (in.target - in.q); }
  double gain;
};

}  // namespace nao::tools
