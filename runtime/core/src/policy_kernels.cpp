// The policy kernels' names and the CPU's support for them (nao/policy_kernels.hpp): pure
// functions of the machine, no environment and no state.
#include "nao/policy_kernels.hpp"

#include <stdexcept>
#include <string>

namespace nao {

namespace {

// __builtin_cpu_init is idempotent and cheap; calling it makes the answer right even before the
// compiler runtime's own constructor ran (a caller's static initialiser).
bool cpuHasAvx2() noexcept {
#if NAO_POLICY_HAVE_AVX2
  // Also checks that the OS saves the ymm state (GCC's and Clang's cpu model do).
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") != 0;
#else
  return false;
#endif
}

bool cpuHasAvx512() noexcept {
#if NAO_POLICY_HAVE_AVX2
  // The kernel's instructions: AVX-512 F (zmm arithmetic), BW (vpmovsxbw to zmm), VNNI
  // (vpdpwssd); its window attention is AVX2. GCC's cpu model also checks the OS's XCR0 for the
  // opmask and zmm state.
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") != 0 && __builtin_cpu_supports("avx512f") != 0 &&
         __builtin_cpu_supports("avx512bw") != 0 && __builtin_cpu_supports("avx512vnni") != 0;
#else
  return false;
#endif
}

}  // namespace

const char* policyKernelName(PolicyKernel k) noexcept {
  switch (k) {
    case PolicyKernel::kAvx2: return "avx2";
    case PolicyKernel::kAvx512: return "avx512";
    case PolicyKernel::kSse: break;
  }
  return "sse";
}

bool parsePolicyKernel(std::string_view name, PolicyKernel& k) noexcept {
  for (PolicyKernel c : {PolicyKernel::kSse, PolicyKernel::kAvx2, PolicyKernel::kAvx512})
    if (name == policyKernelName(c)) {
      k = c;
      return true;
    }
  return false;
}

bool policyKernelSupported(PolicyKernel k) noexcept {
  switch (k) {
    case PolicyKernel::kSse: return true;
    case PolicyKernel::kAvx2: return cpuHasAvx2();
    case PolicyKernel::kAvx512: return cpuHasAvx512();
  }
  return false;
}

PolicyKernel bestPolicyKernel() noexcept {
  if (cpuHasAvx512()) return PolicyKernel::kAvx512;
  return cpuHasAvx2() ? PolicyKernel::kAvx2 : PolicyKernel::kSse;
}

void requirePolicyKernel(PolicyKernel k) {
  if (policyKernelSupported(k)) return;
  throw std::invalid_argument(std::string("policy kernel ") + policyKernelName(k) +
                              ": not supported by this CPU or build (the best here is " +
                              policyKernelName(bestPolicyKernel()) + ")");
}

}  // namespace nao
