// Fault injection for the controller's tests: the policy's own action with a NaN on chosen
// ticks, an ActionLaw around policyAction, so the tick's non-finite path (the command limiter
// holds, kFaultPolicyNonFinite) runs without a hook in the controller.
#pragma once

#include "nao/controller.hpp"

#include <cstdint>
#include <limits>

namespace nao::test {

template <class Dims>
struct PolicyWithNan final : ActionLaw {
  /// NaN in joint 0's action on ticks first..last; the policy's action on every other tick.
  PolicyWithNan(const ControllerModel<Dims>& model, ControllerData<Dims>& data, std::int64_t first, std::int64_t last)
      : model_(&model), data_(&data), first_(first), last_(last) {}
  const char* name() const override { return "policy with NaN"; }
  JointVector action(const ActionInput& in) override {
    JointVector a = policyAction(*model_, *data_, in);
    if (in.tick >= first_ && in.tick <= last_) a[0] = std::numeric_limits<double>::quiet_NaN();
    return a;
  }

 private:
  const ControllerModel<Dims>* model_;
  ControllerData<Dims>* data_;
  std::int64_t first_, last_;
};

}  // namespace nao::test
