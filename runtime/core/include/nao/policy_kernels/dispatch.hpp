// The choice of the policy kernel: the implementations of the policy's one hot loop,
// Y = W X + b over J token columns (affineTokens, nao/policy_kernels/affine.hpp), and of the
// other kernel families (nao/policy_kernels.hpp lists them), chosen once at run time
// (docs/policy.md, "Kernel dispatch").
//
//   kSse   Eigen's packet at the build's baseline width: Packet4f (SSE2) on x86-64 without
//          -march flags, which is what the NAO V6's Atom E3845 runs (SSE4.2, no AVX).
//   kAvx2  8-wide AVX2 intrinsics in __attribute__((target("avx2"))) functions, picked when the
//          CPU has AVX2 (x86-64 with GCC or Clang only; elsewhere only kSse exists).
//   kAvx512 16-wide AVX-512 intrinsics (target("avx512f,avx512bw,avx512vnni")) for the matrix
//          products, fp32 and int8 (vpdpbusd); the window attention keeps the AVX2 kernels.
//          Picked when the CPU has AVX2, AVX-512 F/BW and AVX512-VNNI (and the OS saves the zmm
//          state). Built wherever kAvx2 is (NAO_POLICY_HAVE_AVX2; the NAO preset has neither).
//
// Every family's kernels give the same bits (each family's header says how), so the choice
// changes only the speed.
//
// Selection: the first use (normally bindPolicyWeights, i.e. configure time) reads the
// environment variable NAO_POLICY_KERNEL (unset, "" or "auto": the best the CPU supports;
// "sse": force kSse; "avx2": kAvx2 if supported, else kSse; "avx512": kAvx512 if supported, else
// the best below it; anything else: auto) and caches the
// result. selectPolicyKernel overrides it (tests, benchmarks). The real-time cost is one relaxed
// atomic load per affineTokens call.
#pragma once

#include <atomic>

// The AVX2 kernel exists in x86-64 GCC/Clang builds (target attribute, __builtin_cpu_supports).
// -DNAO_POLICY_HAVE_AVX2=0 (the whole build) leaves it out, as on any other platform.
#ifndef NAO_POLICY_HAVE_AVX2
#if defined(__GNUC__) && defined(__x86_64__)
#define NAO_POLICY_HAVE_AVX2 1
#else
#define NAO_POLICY_HAVE_AVX2 0
#endif
#endif
#if NAO_POLICY_HAVE_AVX2
#include <immintrin.h>
#endif
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#if NAO_POLICY_HAVE_AVX2
// The instruction sets of the kAvx512 kernels (target attribute): nothing tagged with it may
// run unless policyKernelSupported(PolicyKernel::kAvx512).
#define NAO_AVX512_TARGET target("avx512f,avx512bw,avx512vnni,avx2")
#endif

namespace nao {

/// The implementations of affineTokens (see the top of this file).
enum class PolicyKernel : int { kSse = 0, kAvx2 = 1, kAvx512 = 2 };

/// "sse", "avx2" or "avx512".
const char* policyKernelName(PolicyKernel k) noexcept;

/// True if this build has the kernel and this CPU can run it (kSse: always).
bool policyKernelSupported(PolicyKernel k) noexcept;

/// Uses kernel k from now on (every thread). Returns false, changing nothing, if k is not
/// supported. Not meant to be called while another thread is inside stepPolicy (harmless, but
/// that step may mix kernels; the results are the same bits either way).
bool selectPolicyKernel(PolicyKernel k) noexcept;

/// The kernel NAO_POLICY_KERNEL and the CPU ask for (what the first use picks), ignoring any
/// selectPolicyKernel call.
PolicyKernel defaultPolicyKernel() noexcept;

namespace detail {

/// The kernel in use as an int; -1 until the first use decides (runtime/core/src/policy_kernels.cpp).
extern std::atomic<int> g_policy_kernel;
/// Decides (environment, CPU) if nobody has yet and returns the kernel in use. No allocation,
/// no I/O.
int resolvePolicyKernel() noexcept;

}  // namespace detail

/// The kernel affineTokens uses. Real-time safe (after the first call: one relaxed load).
inline PolicyKernel activePolicyKernel() noexcept {
  int k = detail::g_policy_kernel.load(std::memory_order_relaxed);
  if (k < 0) k = detail::resolvePolicyKernel();
  return static_cast<PolicyKernel>(k);
}

/// True for the kernels that may run AVX2 code (kAvx512 implies AVX2: its window attention is
/// the AVX2 one).
inline bool policyKernelHasAvx2(PolicyKernel k) noexcept { return k != PolicyKernel::kSse; }

}  // namespace nao
