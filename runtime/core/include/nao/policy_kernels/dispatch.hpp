// The choice of the policy kernel: the implementations of the policy's one hot loop,
// Y = W X + b over J token columns (affineTokens, nao/policy_kernels/affine.hpp), and of the
// other kernel families (nao/policy_kernels.hpp lists them), chosen when the weights are bound
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
// Selection: the kernel is a property of the bound weights (PolicyWeights::kernel), chosen when
// they are bound (bindPolicyWeights, bindPolicyWeightsAt: configure time; by default
// bestPolicyKernel(), the best this CPU runs) and handed to every kernel by stepPolicy. Nothing
// here reads the environment or keeps state: two weights bound with different kernels step side
// by side in one process, each with its own. The real-time cost is one compare per call.
#pragma once

#include <string_view>

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

/// The kernel named `name` ("sse", "avx2", "avx512"; policyKernelName's names) into k; false,
/// k unchanged, for any other name. Whether this CPU runs it is policyKernelSupported's question.
bool parsePolicyKernel(std::string_view name, PolicyKernel& k) noexcept;

/// True if this build has the kernel and this CPU can run it (kSse: always). Asks the CPU each
/// time (cpuid as the compiler's runtime caches it): a pure function of the machine.
bool policyKernelSupported(PolicyKernel k) noexcept;

/// The fastest kernel this build has and this CPU runs: kAvx512, else kAvx2, else kSse. What
/// the binders pick when not told otherwise. Pure (no environment, no state).
PolicyKernel bestPolicyKernel() noexcept;

/// Throws std::invalid_argument naming the kernel and what this CPU runs when k is not
/// supported (policyKernelSupported): the binders' check, configure time.
void requirePolicyKernel(PolicyKernel k);

/// True for the kernels that may run AVX2 code (kAvx512 implies AVX2: its window attention is
/// the AVX2 one).
inline bool policyKernelHasAvx2(PolicyKernel k) noexcept { return k != PolicyKernel::kSse; }

}  // namespace nao
