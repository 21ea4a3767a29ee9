// Run-time choice of the policy kernel (nao/policy_kernels.hpp): environment variable
// NAO_POLICY_KERNEL and the CPU's features, decided once and cached.
#include "nao/policy_kernels.hpp"

#include <cstdlib>
#include <cstring>

namespace nao {

namespace {

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

bool policyKernelSupported(PolicyKernel k) noexcept {
  if (k == PolicyKernel::kSse) return true;
  if (k == PolicyKernel::kAvx2) {
    static const bool avx2 = cpuHasAvx2();
    return avx2;
  }
  if (k == PolicyKernel::kAvx512) {
    static const bool avx512 = cpuHasAvx512();
    return avx512;
  }
  return false;
}

PolicyKernel defaultPolicyKernel() noexcept {
  const char* env = std::getenv("NAO_POLICY_KERNEL");
  if (env != nullptr && std::strcmp(env, "sse") == 0) return PolicyKernel::kSse;
  const bool avx2 = policyKernelSupported(PolicyKernel::kAvx2);
  if (env != nullptr && std::strcmp(env, "avx2") == 0) return avx2 ? PolicyKernel::kAvx2 : PolicyKernel::kSse;
  // "avx512", "auto", "", unset, anything else: the best supported.
  if (policyKernelSupported(PolicyKernel::kAvx512)) return PolicyKernel::kAvx512;
  return avx2 ? PolicyKernel::kAvx2 : PolicyKernel::kSse;
}

bool selectPolicyKernel(PolicyKernel k) noexcept {
  if (!policyKernelSupported(k)) return false;
  detail::g_policy_kernel.store(static_cast<int>(k), std::memory_order_relaxed);
  return true;
}

namespace detail {

std::atomic<int> g_policy_kernel{-1};

int resolvePolicyKernel() noexcept {
  int expected = -1;
  // A selectPolicyKernel that got there first wins.
  g_policy_kernel.compare_exchange_strong(expected, static_cast<int>(defaultPolicyKernel()),
                                          std::memory_order_relaxed);
  return g_policy_kernel.load(std::memory_order_relaxed);
}

}  // namespace detail
}  // namespace nao
