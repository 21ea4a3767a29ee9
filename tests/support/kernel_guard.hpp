// Tests that force a policy kernel (selectPolicyKernel) put back the one in use when they end.
#pragma once

#include "nao/policy_kernels.hpp"

namespace nao::test {

/// Restores the kernel in use when it goes out of scope.
struct KernelGuard {
  PolicyKernel saved = activePolicyKernel();
  ~KernelGuard() { selectPolicyKernel(saved); }
};

}  // namespace nao::test
