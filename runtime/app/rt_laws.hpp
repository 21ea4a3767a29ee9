// The evaluation's baselines as action laws in place of the policy (nao/controller.hpp
// ActionLaw): --blend-law-pole and --gain-law. Real-time safe.
#pragma once

#include "nao/controller.hpp"

namespace nao::rt {

/// The key-pose blend law the training labels follow: a = p² a(t−1) + (1 − p)² (r − q).
struct BlendLaw final : ActionLaw {
  explicit BlendLaw(double p) : pole(p) {}
  const char* name() const override { return "blend law"; }
  JointVector action(const ActionInput& in) override {
    return pole * pole * in.a_prev + (1.0 - pole) * (1.0 - pole) * (in.key_pose - in.q);
  }
  double pole;
};

/// The fixed-gain inversion of a first-order servo on the feature-extracted target:
/// a = g (clamp(f(t+1)) − q).
struct GainLaw final : ActionLaw {
  explicit GainLaw(double g) : gain(g) {}
  const char* name() const override { return "gain law"; }
  JointVector action(const ActionInput& in) override { return gain * (in.target - in.q); }
  double gain;
};

}  // namespace nao::rt
