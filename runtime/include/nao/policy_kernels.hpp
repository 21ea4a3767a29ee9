// The policy's one hot loop: Y = W X + b over J token columns (affineTokens), with the kernel
// chosen once at run time (docs/policy.md, "Kernel dispatch").
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
// All compute every Y(r, t) as b(r) + W(r,0) X(0,t) + W(r,1) X(1,t) + ... in k order, one
// rounded multiply then one rounded add per term (never fused: -ffp-contract=off, and the AVX2
// functions are compiled without the FMA ISA), so the two give bit-identical results; the lane
// width only changes how many rows are computed at once (tests/test_policy_kernels.cpp).
//
// Selection: the first use (normally bindPolicyWeights, i.e. configure time) reads the
// environment variable NAO_POLICY_KERNEL (unset, "" or "auto": the best the CPU supports;
// "sse": force kSse; "avx2": kAvx2 if supported, else kSse; "avx512": kAvx512 if supported, else
// the best below it; anything else: auto) and caches the
// result. selectPolicyKernel overrides it (tests, benchmarks). The real-time cost is one relaxed
// atomic load per affineTokens call.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

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

/// The kernel in use as an int; -1 until the first use decides (runtime/src/policy_kernels.cpp).
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

namespace detail {

// ---------------------------------------------------------------------------------------------
// The parts every fp32 kernel shares (no vector width in them, so the same bits anywhere).

/// Y(:, t) = b, or 0 without a bias, for every token: where every kernel's sums start.
template <int Out, int J>
inline void initTokens(const float* b, float* Y) {
  for (int t = 0; t < J; ++t)
    for (int r = 0; r < Out; ++r) Y[t * Out + r] = b != nullptr ? b[r] : 0.0f;
}

/// Rows r0 .. Out−1 of Y(:, t) += W(:, k0 .. k0+kc−1) X(k0 .. k0+kc−1, t), all t, one at a time
/// in k order: the rows a vector kernel's blocks leave over.
template <int Out, int In, int J>
inline void accumulateRowsScalar(const float* W, const float* X, float* Y, int k0, int kc, int r0) {
  for (int r = r0; r < Out; ++r)
    for (int t = 0; t < J; ++t) {
      float s = Y[t * Out + r];
      for (int k = k0; k < k0 + kc; ++k) s += W[static_cast<std::ptrdiff_t>(k) * Out + r] * X[t * In + k];
      Y[t * Out + r] = s;
    }
}

/// Y = max(Y, 0) over every token.
template <int Out, int J>
inline void reluTokens(float* Y) {
  for (int i = 0; i < Out * J; ++i) Y[i] = std::max(Y[i], 0.0f);
}

// ---------------------------------------------------------------------------------------------
// kSse: Eigen packets at the baseline width.

using Packet = Eigen::internal::packet_traits<float>::type;
inline constexpr int kPacketSize = Eigen::internal::packet_traits<float>::size;

/// Y(:, t) += W(:, k0 .. k0+NK-1) X(k0 .. k0+NK-1, t) for all t, in k order.
/// W column-major [Out, In], X [In, J] and Y [Out, J] column-major. Blocks of 2 packets of
/// rows keep 2J accumulators in registers while NK consecutive columns of W stream by, so the
/// panel (NK·Out contiguous floats) is read once for all J tokens.
template <int Out, int In, int J, int NK>
inline void accumulatePanel(const float* W, const float* X, float* Y, int k0) {
  using Eigen::internal::padd;
  using Eigen::internal::pmul;
  using Eigen::internal::ploadu;
  using Eigen::internal::pstoreu;
  constexpr int P = kPacketSize;
  constexpr int kRows = 2 * P;
  Packet x_splat[NK][J];
  for (int kk = 0; kk < NK; ++kk)
    for (int t = 0; t < J; ++t) x_splat[kk][t] = Eigen::internal::pset1<Packet>(X[t * In + k0 + kk]);
  const float* Wp = W + static_cast<std::ptrdiff_t>(k0) * Out;
  int r = 0;
  for (; r + kRows <= Out; r += kRows) {
#if defined(__GNUC__)
    // Pull the next panel (or, after the last one, the next tensor of model.bin) toward the
    // cache in step with this one: the hardware prefetcher alone left the streamed weights
    // ~2x slower than the arithmetic (measured, 24 MB sweep).
    {
      const char* next = reinterpret_cast<const char*>(Wp + NK * Out) +
                         static_cast<std::ptrdiff_t>(r / kRows) * NK * kRows * static_cast<int>(sizeof(float));
      for (int byte = 0; byte < NK * kRows * static_cast<int>(sizeof(float)); byte += 64) __builtin_prefetch(next + byte);
    }
#endif
    Packet acc0[J], acc1[J];
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      acc0[t] = ploadu<Packet>(Y + t * Out + r);
      acc1[t] = ploadu<Packet>(Y + t * Out + r + P);
    }
#pragma GCC unroll 16
    for (int kk = 0; kk < NK; ++kk) {
      const Packet w0 = ploadu<Packet>(Wp + kk * Out + r);
      const Packet w1 = ploadu<Packet>(Wp + kk * Out + r + P);
#pragma GCC unroll 8
      for (int t = 0; t < J; ++t) {
        // Multiply then add, never fused: the same rounding as the scalar rows below.
        acc0[t] = padd(acc0[t], pmul(w0, x_splat[kk][t]));
        acc1[t] = padd(acc1[t], pmul(w1, x_splat[kk][t]));
      }
    }
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      pstoreu(Y + t * Out + r, acc0[t]);
      pstoreu(Y + t * Out + r + P, acc1[t]);
    }
  }
  // Rows left over when Out is not a multiple of the block: same order of operations.
  for (; r < Out; ++r)
    for (int t = 0; t < J; ++t) {
      float s = Y[t * Out + r];
      for (int kk = 0; kk < NK; ++kk) s += Wp[kk * Out + r] * X[t * In + k0 + kk];
      Y[t * Out + r] = s;
    }
}

/// affineTokens with the kSse kernel.
template <int Out, int In, int J, bool kRelu>
inline void affineTokensSse(const float* W, const float* b, const float* X, float* Y) {
  // 4 columns x 2 packets x J tokens: measured fastest of 2-16 columns, 1-3 packets (SSE2).
  constexpr int kPanel = 4;
  initTokens<Out, J>(b, Y);
  for (int k0 = 0; k0 + kPanel <= In; k0 += kPanel) accumulatePanel<Out, In, J, kPanel>(W, X, Y, k0);
  if constexpr (In % kPanel != 0) accumulatePanel<Out, In, J, In % kPanel>(W, X, Y, In - In % kPanel);
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}

#if NAO_POLICY_HAVE_AVX2
// ---------------------------------------------------------------------------------------------
// kAvx2: 8-wide intrinsics in target("avx2") functions (not "fma": the compiler could not fuse
// the multiply and the add even if asked to). Nothing here may run unless
// policyKernelSupported(PolicyKernel::kAvx2).
//
// Loop order: W is cut into strips of kAvx2Strip consecutive columns (one contiguous range of
// model.bin); for each block of 16 rows the 2·J accumulators stay in ymm registers while the
// strip's columns go by (k inner), so Y is loaded and stored once per strip, not per column.
// Per column and block: 2 loads of W (one 64-byte line: model.bin tensors are 64-byte aligned
// and Out is a multiple of 16 in the paper and small configurations), J broadcasts of X(k, t),
// 2J multiplies and 2J adds. 2·J = 10 accumulators + 2 weights + 1 broadcast fit the 16 ymm registers; 3
// packets of rows (15 accumulators) spill.
// While a strip is computed, the next one is prefetched in address order (each block of rows,
// each column: one line), so the memory stream stays one strip ahead and sequential.
// Measured on the paper model (AMD EPYC, 2 vCPUs, 24 MB of weights streamed per step, step
// time / time of a bare read of the same bytes, interleaved): this order ~1.0-1.1x; the same
// with strided prefetches (the same rows 16 columns ahead) ~1.15-1.4x; no software prefetch
// ~2.5x; the panel order of the kSse kernel at 8 lanes (Y through memory every 2-4 columns)
// ~1.3-1.5x. Strips of 8 to 24 columns were within noise of each other.

/// Columns of W per strip.
inline constexpr int kAvx2Strip = 16;

/// Rows r .. r+8R-1 of Y(:, t) += W(:, k0 .. k0+kc-1) X(k0 .. k0+kc-1, t), all t, in k order,
/// with R·J accumulators in registers.
template <int Out, int In, int J, int R>
__attribute__((target("avx2"), always_inline)) inline void accumulateStripAvx2(const float* W, const float* X, float* Y,
                                                                                int k0, int kc, int r) {
  __m256 acc[R][J];
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) acc[i][t] = _mm256_loadu_ps(Y + t * Out + r + 8 * i);
  const float* Wk = W + static_cast<std::ptrdiff_t>(k0) * Out + r;
  const float* Xk = X + k0;
  // The next strip (kc·Out contiguous floats right after this one; after the last strip, the
  // next tensor of model.bin), read in order: this block's share is kc lines starting at r·kc.
  const float* next = W + static_cast<std::ptrdiff_t>(k0 + kc) * Out;
#pragma GCC unroll 2
  for (int k = 0; k < kc; ++k) {
    // Locality 2: toward L2 (a 512-row strip is 32 KB, the size of L1).
    __builtin_prefetch(next + static_cast<std::ptrdiff_t>(r) * kc + 16 * k, 0, 2);
    __m256 w[R];
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) w[i] = _mm256_loadu_ps(Wk + static_cast<std::ptrdiff_t>(k) * Out + 8 * i);
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      const __m256 x = _mm256_broadcast_ss(Xk + t * In + k);
      // Multiply then add, never fused: the same rounding as kSse and the scalar rows.
#pragma GCC unroll 4
      for (int i = 0; i < R; ++i) acc[i][t] = _mm256_add_ps(acc[i][t], _mm256_mul_ps(w[i], x));
    }
  }
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) _mm256_storeu_ps(Y + t * Out + r + 8 * i, acc[i][t]);
}

/// affineTokens with the kAvx2 kernel (the CPU must support AVX2): strips of columns; in each,
/// blocks of 16 rows, then of 8, then single rows (scalar, same order of operations).
template <int Out, int In, int J, bool kRelu>
__attribute__((target("avx2"), noinline)) void affineTokensAvx2(const float* W, const float* b, const float* X,
                                                                 float* Y) {
  initTokens<Out, J>(b, Y);
  for (int k0 = 0; k0 < In; k0 += kAvx2Strip) {
    const int kc = std::min(kAvx2Strip, In - k0);
    int r = 0;
    for (; r + 16 <= Out; r += 16) accumulateStripAvx2<Out, In, J, 2>(W, X, Y, k0, kc, r);
    for (; r + 8 <= Out; r += 8) accumulateStripAvx2<Out, In, J, 1>(W, X, Y, k0, kc, r);
    accumulateRowsScalar<Out, In, J>(W, X, Y, k0, kc, r);
  }
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}

// ---------------------------------------------------------------------------------------------
// kAvx512: the kAvx2 loop order at 16 lanes (strips of kAvx2Strip columns; blocks of 32 rows,
// 2·J zmm accumulators; the next strip prefetched in address order, two lines per column and
// block). Multiply then add, never fused, each row's terms in k order: the same bits as kSse
// and kAvx2. Nothing here may run unless policyKernelSupported(PolicyKernel::kAvx512).
#define NAO_AVX512_TARGET target("avx512f,avx512bw,avx512vnni,avx2")

/// The 16 lanes of v folded in halves: lane l with l + 8, then l + 4, l + 2, l + 1, by max
/// (kMax; exact in any order when no lane is NaN) or by add (that order is part of
/// headSumNorm's bits).
template <bool kMax>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline float foldLanesAvx512(__m512 v) noexcept {
  // Zero-masked extracts (GCC 12 warns on the unmasked ones, see kAll).
  const __m512d vd = _mm512_castps_pd(v);
  const __m256 lo = _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xff, vd, 0));
  const __m256 hi = _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xff, vd, 1));
  if constexpr (kMax) {
    const __m256 y = _mm256_max_ps(lo, hi);
    __m128 x = _mm_max_ps(_mm256_castps256_ps128(y), _mm256_extractf128_ps(y, 1));
    x = _mm_max_ps(x, _mm_movehl_ps(x, x));
    return _mm_cvtss_f32(_mm_max_ss(x, _mm_shuffle_ps(x, x, 1)));
  } else {
    const __m256 y = _mm256_add_ps(lo, hi);
    __m128 x = _mm_add_ps(_mm256_castps256_ps128(y), _mm256_extractf128_ps(y, 1));
    x = _mm_add_ps(x, _mm_movehl_ps(x, x));
    return _mm_cvtss_f32(_mm_add_ss(x, _mm_shuffle_ps(x, x, 1)));
  }
}

/// The first min(max(count, 0), 16) lanes of a zmm register: the mask of a row's tail.
constexpr __mmask16 laneMask16(int count) noexcept {
  return count >= 16 ? static_cast<__mmask16>(0xffff)
                     : static_cast<__mmask16>((1u << (count > 0 ? count : 0)) - 1u);
}

/// Rows r .. r+16R-1 of Y(:, t) += W(:, k0 .. k0+kc-1) X(k0 .. k0+kc-1, t), all t, in k order.
template <int Out, int In, int J, int R>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline void accumulateStripAvx512(const float* W, const float* X,
                                                                                  float* Y, int k0, int kc, int r) {
  __m512 acc[R][J];
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) acc[i][t] = _mm512_loadu_ps(Y + t * Out + r + 16 * i);
  const float* Wk = W + static_cast<std::ptrdiff_t>(k0) * Out + r;
  const float* Xk = X + k0;
  // This block's share of the next strip: R·kc lines from r·kc (see accumulateStripAvx2).
  const float* next = W + static_cast<std::ptrdiff_t>(k0 + kc) * Out + static_cast<std::ptrdiff_t>(r) * kc;
#pragma GCC unroll 2
  for (int k = 0; k < kc; ++k) {
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) __builtin_prefetch(next + 16 * (R * k + i), 0, 2);
    __m512 w[R];
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) w[i] = _mm512_loadu_ps(Wk + static_cast<std::ptrdiff_t>(k) * Out + 16 * i);
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      const __m512 x = _mm512_set1_ps(Xk[t * In + k]);
#pragma GCC unroll 4
      for (int i = 0; i < R; ++i) acc[i][t] = _mm512_add_ps(acc[i][t], _mm512_mul_ps(w[i], x));
    }
  }
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 4
    for (int i = 0; i < R; ++i) _mm512_storeu_ps(Y + t * Out + r + 16 * i, acc[i][t]);
}

/// affineTokens with the kAvx512 kernel: strips of columns; in each, blocks of 32 rows, then
/// of 16, then the AVX2 kernel's 8-row block and single rows (same order of operations).
template <int Out, int In, int J, bool kRelu>
__attribute__((NAO_AVX512_TARGET, noinline)) void affineTokensAvx512(const float* W, const float* b, const float* X,
                                                                      float* Y) {
  initTokens<Out, J>(b, Y);
  for (int k0 = 0; k0 < In; k0 += kAvx2Strip) {
    const int kc = std::min(kAvx2Strip, In - k0);
    int r = 0;
    for (; r + 32 <= Out; r += 32) accumulateStripAvx512<Out, In, J, 2>(W, X, Y, k0, kc, r);
    for (; r + 16 <= Out; r += 16) accumulateStripAvx512<Out, In, J, 1>(W, X, Y, k0, kc, r);
    for (; r + 8 <= Out; r += 8) accumulateStripAvx2<Out, In, J, 1>(W, X, Y, k0, kc, r);
    accumulateRowsScalar<Out, In, J>(W, X, Y, k0, kc, r);
  }
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}
#endif  // NAO_POLICY_HAVE_AVX2

// ---------------------------------------------------------------------------------------------
// Reduced precision (docs/policy.md "int8 weights"): W as int8 with one scale per output row,
// the tokens quantised per column on the fly, products summed exactly in int32.
//
//   Wq  int8, pairs of input columns interleaved: byte (p·Out + r)·2 + e holds
//       round(W(r, 2p + e) / sw(r)), |·| <= 127 (quantizeMatrixInt8, runtime/src/quantize.cpp)
//   sw  float [Out], max_k |W(r, k)| / 127
//   X   one range per product, L levels: if no entry of X is negative (the FFN's inputs after
//       its ReLUs, 78 % of the paper model's weights) L = 255 (8 bits, unsigned), else
//       L = 32767 (16 bits, signed); each column t: xq = round(X(:, t) · L / max|X(:, t)|),
//       sx(t) = max|X(:, t)| / L (quantizeTokensInt8)
//   Y(r, t) = b(r) + float(Σ_k Wq(r, k) xq(k, t)) · (sw(r) · sx(t))
//
// SSE2 and AVX2: one pmaddwd multiplies a row's pair of int8 weights (sign-extended to int16) by
// the token's pair of xq (as int16) and adds the two products into an int32 lane. AVX-512 VNNI:
// 8-bit tokens go through vpdpbusd (four unsigned token bytes times four signed weights, and
// the accumulator, in one instruction: 64 products per zmm), 16-bit ones through vpdpwssd (32).
// 8 bits everywhere measured 3.5x the action error for 5 % less time (docs/policy.md). Integer
// sums are exact (|Σ| <= 512 · 127 · 32767 < 2^31 for In <= 512), so every kernel gives the same
// bits in any order; only the final conversion and two multiplies round (in one fixed order).

/// Largest In the int32 accumulators of the int8 kernels cannot overflow for.
inline constexpr int kInt8MaxIn = 512;

/// The J columns of one product quantised (quantizeTokensInt8 fills pairs, sx and positive; its
/// AVX-512 form also quads when positive). Lives on the stack of affineTokensInt8.
template <int In, int J>
struct QuantTokens {
  static constexpr int kPairs = In / 2;
  static constexpr int kQuads = In % 4 == 0 ? In / 4 : 0;  ///< byte quads only when In % 4 == 0
  /// Lane p of column t: xq(2p, t) in the low int16, xq(2p + 1, t) in the high one.
  alignas(64) std::int32_t pairs[J * kPairs];
  /// Lane q of column t: the four bytes xq(4q .. 4q + 3, t) (vpdpbusd's broadcast operand).
  alignas(64) std::int32_t quads[J * (kQuads > 0 ? kQuads : 1)];
  float sx[J];
  bool positive;  ///< xq in [0, 255] (no negative entry in X), else in [-32767, 32767]
};

/// The largest quantised magnitude of a product's range.
inline constexpr float int8TokenLevels(bool positive) { return positive ? 255.0f : 32767.0f; }

/// Entries k0 .. n−1 of one token (k0 even) as int16 pairs: round-to-nearest-even(x · inv),
/// clamped to [lo, hi] (the vector quantisers' tails).
inline void quantizePairsScalar(const float* x, std::int32_t* out, int k0, int n, float inv, float lo, float hi) {
  for (int k = k0; k < n; k += 2) {
    const auto q0 = static_cast<std::int32_t>(std::clamp(std::nearbyint(x[k] * inv), lo, hi));
    const auto q1 = static_cast<std::int32_t>(std::clamp(std::nearbyint(x[k + 1] * inv), lo, hi));
    out[k / 2] = static_cast<std::int32_t>(static_cast<std::uint32_t>(q0 & 0xffff) | (static_cast<std::uint32_t>(q1) << 16));
  }
}

/// Quantises the J columns of X [In, J] (column-major) into x.pairs, x.sx and x.positive (the
/// ranges above). A column with a non-finite entry gets xq = 0 and sx = NaN, so its outputs are
/// NaN as in the fp32 path; an all-zero column gets sx = 0. Does not fill quads.
template <int In, int J>
inline void quantizeTokensInt8(const float* X, QuantTokens<In, J>& x) {
  static_assert(In % 2 == 0, "the int8 kernels take input columns in pairs");
  // Pass 1: per column max |x| and whether every x is finite (x·0 is NaN exactly for ±inf and
  // NaN); over all columns whether any x < 0 (false for NaN).
  float mx[J], poison[J];
  bool negative = false;
  for (int t = 0; t < J; ++t) {
    const float* xc = X + t * In;
    float m = 0.0f, p = 0.0f;
    int k = 0;
#if defined(__SSE2__)
    {
      const __m128 sign = _mm_set1_ps(-0.0f), zero = _mm_setzero_ps();
      __m128 vm = zero, vp = zero, vn = zero;
      for (; k + 4 <= In; k += 4) {
        const __m128 v = _mm_loadu_ps(xc + k);
        vm = _mm_max_ps(vm, _mm_andnot_ps(sign, v));
        vp = _mm_add_ps(vp, _mm_mul_ps(v, zero));
        vn = _mm_or_ps(vn, _mm_cmplt_ps(v, zero));
      }
      alignas(16) float lm[4], lp[4];
      _mm_store_ps(lm, vm);
      _mm_store_ps(lp, vp);
      for (int i = 0; i < 4; ++i) {
        m = std::max(m, lm[i]);
        p += lp[i];
      }
      negative = negative || _mm_movemask_ps(vn) != 0;
    }
#endif
    for (; k < In; ++k) {
      m = std::max(m, std::fabs(xc[k]));
      p += xc[k] * 0.0f;
      negative = negative || xc[k] < 0.0f;
    }
    mx[t] = m;
    poison[t] = p;
  }
  x.positive = !negative;
  const float hi = int8TokenLevels(x.positive), lo = x.positive ? 0.0f : -hi;
  for (int t = 0; t < J; ++t) {
    const float* xc = X + t * In;
    std::int32_t* out = x.pairs + t * (In / 2);
    const float m = mx[t];
    // q = round-to-nearest-even(x · hi / m), in [lo, hi] (the product may round up past hi:
    // clamped). cvtps2dq rounds like nearbyint in the default rounding mode. m below ~1e-36
    // overflows hi / m: the column is zero to within 1e-36 of every input (its products are
    // below what any output can resolve), quantised as zero.
    const float inv = hi / m;
    if (poison[t] != 0.0f || m == 0.0f || !(inv <= std::numeric_limits<float>::max())) {  // NaN != 0
      for (int p = 0; p < In / 2; ++p) out[p] = 0;
      x.sx[t] = poison[t] != 0.0f ? std::numeric_limits<float>::quiet_NaN() : 0.0f;
      continue;
    }
    int k = 0;
#if defined(__SSE2__)
    {
      const __m128 vinv = _mm_set1_ps(inv);
      const __m128i lim = _mm_set1_epi32(static_cast<int>(hi)), nlim = _mm_set1_epi32(static_cast<int>(lo));
      for (; k + 8 <= In; k += 8) {
        __m128i a = _mm_cvtps_epi32(_mm_mul_ps(_mm_loadu_ps(xc + k), vinv));
        __m128i b = _mm_cvtps_epi32(_mm_mul_ps(_mm_loadu_ps(xc + k + 4), vinv));
        // Clamp (SSE2 has no pminsd: compare and blend).
        a = _mm_or_si128(_mm_and_si128(_mm_cmpgt_epi32(a, lim), lim), _mm_andnot_si128(_mm_cmpgt_epi32(a, lim), a));
        a = _mm_or_si128(_mm_and_si128(_mm_cmplt_epi32(a, nlim), nlim), _mm_andnot_si128(_mm_cmplt_epi32(a, nlim), a));
        b = _mm_or_si128(_mm_and_si128(_mm_cmpgt_epi32(b, lim), lim), _mm_andnot_si128(_mm_cmpgt_epi32(b, lim), b));
        b = _mm_or_si128(_mm_and_si128(_mm_cmplt_epi32(b, nlim), nlim), _mm_andnot_si128(_mm_cmplt_epi32(b, nlim), b));
        // Eight int16 in order x[k] .. x[k+7]: as int32 lanes, the pairs (2p, 2p+1).
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k / 2), _mm_packs_epi32(a, b));
      }
    }
#endif
    quantizePairsScalar(xc, out, k, In, inv, lo, hi);
    x.sx[t] = m / hi;
  }
}

/// xq(k, t) of quantised tokens (tests and the scalar rows).
template <int In, int J>
inline int quantToken(const QuantTokens<In, J>& x, int k, int t) {
  const std::int32_t pair = x.pairs[t * (In / 2) + k / 2];
  return static_cast<std::int16_t>(k % 2 == 0 ? (pair & 0xffff) : (pair >> 16));
}

#if NAO_POLICY_HAVE_AVX2
/// quantizeTokensInt8 with 16 lanes (kAvx512): the same maxima, tests, products, roundings and
/// clamps, so the same pairs and scales; also the byte quads of an 8-bit product.
template <int In, int J>
__attribute__((NAO_AVX512_TARGET, noinline)) void quantizeTokensInt8Avx512(const float* X, QuantTokens<In, J>& x) {
  static_assert(In % 2 == 0, "the int8 kernels take input columns in pairs");
  constexpr int kVec = In / 16 * 16;
  // The zero-masked forms with every lane selected: GCC 12's unmasked ones pass an undefined
  // register as the merge source and warn (-Wuninitialized); the results are the same.
  constexpr __mmask16 kAll = 0xffff;
  float mx[J], poison[J];
  bool negative = false;
  for (int t = 0; t < J; ++t) {
    const float* xc = X + t * In;
    float m = 0.0f, p = 0.0f;
    if constexpr (kVec > 0) {
      const __m512 zero = _mm512_setzero_ps();
      __m512 vm = zero, vp = zero;
      __mmask16 neg = 0;
      for (int k = 0; k < kVec; k += 16) {
        const __m512 v = _mm512_loadu_ps(xc + k);
        vm = _mm512_maskz_max_ps(kAll, vm, _mm512_abs_ps(v));
        vp = _mm512_add_ps(vp, _mm512_mul_ps(v, zero));
        neg = static_cast<__mmask16>(neg | _mm512_cmp_ps_mask(v, zero, _CMP_LT_OQ));
      }
      // Folded in lanes, not one by one: a maximum is exact in any order, and a lane of vp is
      // ±0 unless one of its entries was ±inf or NaN, so "some lane NaN" is the sum's test.
      m = foldLanesAvx512<true>(vm);
      p = _mm512_cmp_ps_mask(vp, zero, _CMP_EQ_OQ) == kAll ? 0.0f : std::numeric_limits<float>::quiet_NaN();
      negative = negative || neg != 0;
    }
    for (int k = kVec; k < In; ++k) {
      m = std::max(m, std::fabs(xc[k]));
      p += xc[k] * 0.0f;
      negative = negative || xc[k] < 0.0f;
    }
    mx[t] = m;
    poison[t] = p;
  }
  x.positive = !negative;
  const float hi = int8TokenLevels(x.positive), lo = x.positive ? 0.0f : -hi;
  for (int t = 0; t < J; ++t) {
    const float* xc = X + t * In;
    std::int32_t* out = x.pairs + t * (In / 2);
    auto* bytes = reinterpret_cast<std::int8_t*>(x.quads + t * QuantTokens<In, J>::kQuads);
    const float m = mx[t];
    const float inv = hi / m;
    if (poison[t] != 0.0f || m == 0.0f || !(inv <= std::numeric_limits<float>::max())) {
      // As quantizeTokensInt8: NaN scale for a non-finite column, zero for a (near-)zero one.
      for (int p = 0; p < In / 2; ++p) out[p] = 0;
      if constexpr (QuantTokens<In, J>::kQuads > 0)
        for (int q = 0; q < QuantTokens<In, J>::kQuads; ++q) x.quads[t * QuantTokens<In, J>::kQuads + q] = 0;
      x.sx[t] = poison[t] != 0.0f ? std::numeric_limits<float>::quiet_NaN() : 0.0f;
      continue;
    }
    const bool bytes_too = QuantTokens<In, J>::kQuads > 0 && x.positive;
    if constexpr (kVec > 0) {
      const __m512 vinv = _mm512_set1_ps(inv);
      const __m512i lim = _mm512_set1_epi32(static_cast<int>(hi)), nlim = _mm512_set1_epi32(static_cast<int>(lo));
      for (int k = 0; k < kVec; k += 16) {
        __m512i a = _mm512_maskz_cvtps_epi32(kAll, _mm512_mul_ps(_mm512_loadu_ps(xc + k), vinv));
        a = _mm512_maskz_max_epi32(kAll, _mm512_maskz_min_epi32(kAll, a, lim), nlim);
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + k / 2), _mm512_maskz_cvtepi32_epi16(kAll, a));
        // The low byte of each lane: xq in [0, 255] as an unsigned byte.
        if (bytes_too) _mm_storeu_si128(reinterpret_cast<__m128i*>(bytes + k), _mm512_maskz_cvtepi32_epi8(kAll, a));
      }
    }
    quantizePairsScalar(xc, out, kVec, In, inv, lo, hi);
    if (bytes_too)
      for (int k = kVec; k < In; ++k) bytes[k] = static_cast<std::int8_t>(static_cast<std::uint8_t>(quantToken(x, k, t)));
    x.sx[t] = m / hi;
  }
}
#endif  // NAO_POLICY_HAVE_AVX2

/// Y = b + (acc · (sw · sx)), then ReLU: the int8 kernels' shared epilogue (one order of
/// rounding whatever kernel filled acc [J][Out]; the SSE2 lanes do the same operations).
template <int Out, int J, bool kRelu>
inline void dequantizeTokens(const std::int32_t* acc, const float* sw, const float* sx, const float* b, float* Y) {
  for (int t = 0; t < J; ++t) {
    int r = 0;
#if defined(__SSE2__)
    const __m128 s = _mm_set1_ps(sx[t]), zero = _mm_setzero_ps();
    for (; r + 4 <= Out; r += 4) {
      __m128 y = _mm_mul_ps(_mm_cvtepi32_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(acc + t * Out + r))),
                            _mm_mul_ps(_mm_loadu_ps(sw + r), s));
      if (b != nullptr) y = _mm_add_ps(_mm_loadu_ps(b + r), y);
      // max(0, y): MAXPS returns its second operand when one is NaN, so NaN stays NaN and
      // -0 stays -0, exactly as std::max(y, 0.0f) below and in the fp32 path.
      if constexpr (kRelu) y = _mm_max_ps(zero, y);
      _mm_storeu_ps(Y + t * Out + r, y);
    }
#endif
    for (; r < Out; ++r) {
      float y = static_cast<float>(acc[t * Out + r]) * (sw[r] * sx[t]);
      if (b != nullptr) y = b[r] + y;
      Y[t * Out + r] = kRelu ? std::max(y, 0.0f) : y;
    }
  }
}

#if NAO_POLICY_HAVE_AVX2
/// dequantizeTokens with 16 lanes (kAvx512): the same operations on every element in the same
/// order, so the same bits.
template <int Out, int J, bool kRelu>
__attribute__((NAO_AVX512_TARGET, noinline)) void dequantizeTokensAvx512(const std::int32_t* acc, const float* sw,
                                                                          const float* sx, const float* b, float* Y) {
  constexpr int kVec = Out / 16 * 16;
  constexpr __mmask16 kAll = 0xffff;  // zero-masked forms, as in quantizeTokensInt8Avx512
  for (int t = 0; t < J; ++t) {
    const __m512 s = _mm512_set1_ps(sx[t]), zero = _mm512_setzero_ps();
    for (int r = 0; r < kVec; r += 16) {
      __m512 y = _mm512_mul_ps(_mm512_maskz_cvtepi32_ps(kAll, _mm512_loadu_si512(acc + t * Out + r)),
                               _mm512_mul_ps(_mm512_loadu_ps(sw + r), s));
      if (b != nullptr) y = _mm512_add_ps(_mm512_loadu_ps(b + r), y);
      if constexpr (kRelu) y = _mm512_maskz_max_ps(kAll, zero, y);  // NaN and -0 as MAXPS above
      _mm512_storeu_ps(Y + t * Out + r, y);
    }
    for (int r = kVec; r < Out; ++r) {
      float y = static_cast<float>(acc[t * Out + r]) * (sw[r] * sx[t]);
      if (b != nullptr) y = b[r] + y;
      Y[t * Out + r] = kRelu ? std::max(y, 0.0f) : y;
    }
  }
}
#endif

/// Rows left over by the vector blocks (Out not a multiple of the block): exact int32 sums.
template <int Out, int In, int J>
inline void accumulateRowsInt8Scalar(const std::int8_t* Wq, const std::int32_t* xp, std::int32_t* acc, int r0) {
  for (int r = r0; r < Out; ++r)
    for (int t = 0; t < J; ++t) {
      std::int32_t s = 0;
      for (int p = 0; p < In / 2; ++p) {
        const std::int32_t x = xp[t * (In / 2) + p];
        const auto x0 = static_cast<std::int16_t>(x & 0xffff), x1 = static_cast<std::int16_t>(x >> 16);
        const std::ptrdiff_t i = (static_cast<std::ptrdiff_t>(p) * Out + r) * 2;
        s += Wq[i] * x0 + Wq[i + 1] * x1;
      }
      acc[t * Out + r] = s;
    }
}

/// Pairs of input columns per strip of the int8 kernels: the row blocks of one strip reuse
/// its cache lines (a 16-row block reads 32 bytes of each 64-byte line) while the next strip
/// is prefetched, each block fetching its share (the fp32 kernel's scheme, kAvx2Strip).
inline constexpr int kInt8Strip = 16;

/// Locality hint of the int8 kernels' software prefetch: 0, non-temporal. The int8 weights are
/// read once a step; prefetched with locality 2 their 6 MB passed through L2 and evicted the
/// key/value rings and f_ring (~1.1 MB) the window attention reads next. Measured: the int8
/// step ~10 % faster on this EPYC (bench/results/int8.txt, 2026-11-26; not measured on the
/// Atom); the packed fp32 kernels showed no difference and keep locality 2.
inline constexpr int kInt8PrefetchLocality = 0;

#if defined(__SSE2__)
/// The int8 product with SSE2 (the NAO's Atom and every x86-64): strips of kInt8Strip pairs;
/// in each, blocks of 8 rows with 2·J int32 accumulators in xmm registers.
template <int Out, int In, int J>
inline void accumulateInt8Sse(const std::int8_t* Wq, const std::int32_t* xp, std::int32_t* acc) {
  static_assert(In % 2 == 0 && In <= kInt8MaxIn, "int8 kernel: In even and at most kInt8MaxIn");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 8 * 8;
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    // The next strip of this matrix (none after the last: no address outside it is formed):
    // 16 bytes of it per pair and block of this strip, so the block's share is pc·16 bytes.
    const bool more = p0 + pc < P;
    const std::int8_t* next = Wq + static_cast<std::ptrdiff_t>(p0 + pc) * Out * 2;
    for (int r = 0; r < kRows; r += 8) {
      // Fresh sums per strip, added to acc after it (fewer live registers than carrying acc).
      __m128i a0[J], a1[J];
      for (int t = 0; t < J; ++t) a0[t] = a1[t] = _mm_setzero_si128();
      const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
      const std::int8_t* share = more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr;
#pragma GCC unroll 2
      for (int i = 0; i < pc; ++i) {
#if defined(__GNUC__)
        if (more && (i & 3) == 0) __builtin_prefetch(share + 16 * i, 0, kInt8PrefetchLocality);
#endif
        const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(w + static_cast<std::ptrdiff_t>(i) * Out * 2));
        // Sign-extend bytes to int16 (SSE2: duplicate each byte into a word, shift right).
        const __m128i lo = _mm_srai_epi16(_mm_unpacklo_epi8(v, v), 8);  // rows r..r+3, both columns
        const __m128i hi = _mm_srai_epi16(_mm_unpackhi_epi8(v, v), 8);  // rows r+4..r+7
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t) {
          const __m128i x = _mm_set1_epi32(xp[t * P + p0 + i]);
          a0[t] = _mm_add_epi32(a0[t], _mm_madd_epi16(lo, x));
          a1[t] = _mm_add_epi32(a1[t], _mm_madd_epi16(hi, x));
        }
      }
      for (int t = 0; t < J; ++t) {
        auto* y0 = reinterpret_cast<__m128i*>(acc + t * Out + r);
        auto* y1 = reinterpret_cast<__m128i*>(acc + t * Out + r + 4);
        _mm_storeu_si128(y0, p0 == 0 ? a0[t] : _mm_add_epi32(_mm_loadu_si128(y0), a0[t]));
        _mm_storeu_si128(y1, p0 == 0 ? a1[t] : _mm_add_epi32(_mm_loadu_si128(y1), a1[t]));
      }
    }
  }
  if constexpr (Out % 8 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, xp, acc, kRows);
}
#endif  // __SSE2__

#if NAO_POLICY_HAVE_AVX2
/// The int8 product with AVX2: strips of kInt8Strip pairs; in each, blocks of 8 rows (16
/// weight bytes per pair, sign-extended by one vpmovsxbw load), J int32 accumulators in ymm
/// registers (with 16 rows and 2·J accumulators GCC spilled them: measured slower).
template <int Out, int In, int J>
__attribute__((target("avx2"), noinline)) void accumulateInt8Avx2(const std::int8_t* Wq, const std::int32_t* xp,
                                                                    std::int32_t* acc) {
  static_assert(In % 2 == 0 && In <= kInt8MaxIn, "int8 kernel: In even and at most kInt8MaxIn");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 8 * 8;
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    const bool more = p0 + pc < P;  // the next strip of this matrix, as in the SSE2 kernel
    const std::int8_t* next = Wq + static_cast<std::ptrdiff_t>(p0 + pc) * Out * 2;
    for (int r = 0; r < kRows; r += 8) {
      __m256i a[J];
      for (int t = 0; t < J; ++t) a[t] = _mm256_setzero_si256();
      const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
      const std::int8_t* share = more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr;  // pc·16 bytes
#pragma GCC unroll 4
      for (int i = 0; i < pc; ++i) {
        if (more && (i & 3) == 0) __builtin_prefetch(share + 16 * i, 0, kInt8PrefetchLocality);
        const __m256i v = _mm256_cvtepi8_epi16(
            _mm_loadu_si128(reinterpret_cast<const __m128i*>(w + static_cast<std::ptrdiff_t>(i) * Out * 2)));
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t)
          a[t] = _mm256_add_epi32(a[t], _mm256_madd_epi16(v, _mm256_set1_epi32(xp[t * P + p0 + i])));
      }
      for (int t = 0; t < J; ++t) {
        auto* y = reinterpret_cast<__m256i*>(acc + t * Out + r);
        _mm256_storeu_si256(y, p0 == 0 ? a[t] : _mm256_add_epi32(_mm256_loadu_si256(y), a[t]));
      }
    }
  }
  if constexpr (Out % 8 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, xp, acc, kRows);
}

/// The share of the next strip of an int8 matrix (pairs p0 + pc ..) that the block of rows from
/// r prefetches: R·pc·32 bytes from r·2·pc (the strip's bytes split evenly among its blocks), or
/// null after the last strip (no address outside the matrix is formed).
template <int Out, int R>
inline const std::int8_t* nextStripShare(const std::int8_t* Wq, int P, int p0, int pc, int r) {
  return p0 + pc < P ? Wq + static_cast<std::ptrdiff_t>(p0 + pc) * Out * 2 + static_cast<std::ptrdiff_t>(r) * 2 * pc
                     : nullptr;
}

/// Stores one strip's sums a[i][t] (rows r + 16i of token t) into acc, or adds them after the
/// first strip (the AVX-512 int8 kernels: fresh sums per strip).
template <int Out, int J, int R>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline void storeStripSumsAvx512(const __m512i (&a)[R][J],
                                                                                  std::int32_t* acc, int r,
                                                                                  bool first) {
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
    for (int i = 0; i < R; ++i) {
      std::int32_t* y = acc + t * Out + r + 16 * i;
      _mm512_storeu_si512(y, first ? a[i][t] : _mm512_add_epi32(_mm512_loadu_si512(y), a[i][t]));
    }
}

/// Rows r .. r+16R-1 of the int8 product over pairs p0 .. p0+pc-1 (one strip), for
/// accumulateInt8Avx512.
template <int Out, int In, int J, int R>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline void accumulateInt8BlockAvx512(const std::int8_t* Wq,
                                                                                      const std::int32_t* xp,
                                                                                      std::int32_t* acc, int p0,
                                                                                      int pc, int r) {
  constexpr int P = In / 2;
  // The block's share of the next strip, one line every 2/R pairs.
  const std::int8_t* share = nextStripShare<Out, R>(Wq, P, p0, pc, r);
  const bool more = share != nullptr;
  __m512i a[R][J];
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
    for (int i = 0; i < R; ++i) a[i][t] = _mm512_setzero_si512();
  const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
#pragma GCC unroll 4
  for (int k = 0; k < pc; ++k) {
    if (more && (k & (2 / R - 1)) == 0) __builtin_prefetch(share + 32 * R * k, 0, kInt8PrefetchLocality);
    __m512i v[R];
#pragma GCC unroll 2
    for (int i = 0; i < R; ++i)
      v[i] = _mm512_cvtepi8_epi16(
          _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w + static_cast<std::ptrdiff_t>(k) * Out * 2 + 32 * i)));
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      const __m512i x = _mm512_set1_epi32(xp[t * P + p0 + k]);
#pragma GCC unroll 2
      for (int i = 0; i < R; ++i) a[i][t] = _mm512_dpwssd_epi32(a[i][t], v[i], x);
    }
  }
  storeStripSumsAvx512<Out, J, R>(a, acc, r, p0 == 0);
}

/// The int8 product with AVX-512 VNNI: strips of kInt8Strip pairs; in each, blocks of 32 rows
/// (one 64-byte line per pair: two vpmovsxbw loads of 16 rows), 2·J int32 accumulators in zmm
/// registers, each pair added by one vpdpwssd (both int16 products and the accumulator in one
/// instruction, wrapping like pmaddwd + paddd; no sum here comes near 2^31, see above). Rows
/// left over: a block of 16, then the scalar rows.
template <int Out, int In, int J>
__attribute__((NAO_AVX512_TARGET, noinline)) void accumulateInt8Avx512(const std::int8_t* Wq, const std::int32_t* xp,
                                                                        std::int32_t* acc) {
  static_assert(In % 2 == 0 && In <= kInt8MaxIn, "int8 kernel: In even and at most kInt8MaxIn");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 16 * 16;
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    int r = 0;
    for (; r + 32 <= kRows; r += 32) accumulateInt8BlockAvx512<Out, In, J, 2>(Wq, xp, acc, p0, pc, r);
    for (; r < kRows; r += 16) accumulateInt8BlockAvx512<Out, In, J, 1>(Wq, xp, acc, p0, pc, r);
  }
  if constexpr (Out % 16 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, xp, acc, kRows);
}

/// Rows r .. r+16R-1 of the product of 8-bit tokens over pairs p0 .. p0+pc-1 (one strip, pc
/// even) with vpdpbusd, for accumulateInt8QuadsAvx512. Each quad of inputs reads the lines of
/// pairs 2k and 2k+1 and interleaves their words (vpermt2w), so each int32 lane holds one row's
/// four consecutive weights.
template <int Out, int In, int J, int R>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline void accumulateInt8QuadBlockAvx512(
    const std::int8_t* Wq, const QuantTokens<In, J>& x, std::int32_t* acc, int p0, int pc, int r) {
  constexpr int P = In / 2, Q = QuantTokens<In, J>::kQuads;
  // The block's share of the next strip, R lines per quad.
  const std::int8_t* share = nextStripShare<Out, R>(Wq, P, p0, pc, r);
  const bool more = share != nullptr;
  // Word indices: lane i of the result is (row i of pair 2k, row i of pair 2k+1).
  alignas(64) static constexpr std::int16_t kLo[32] = {0, 32, 1, 33, 2, 34, 3, 35, 4, 36, 5, 37, 6, 38, 7, 39,
                                                       8, 40, 9, 41, 10, 42, 11, 43, 12, 44, 13, 45, 14, 46, 15, 47};
  alignas(64) static constexpr std::int16_t kHi[32] = {16, 48, 17, 49, 18, 50, 19, 51, 20, 52, 21, 53, 22, 54, 23, 55,
                                                       24, 56, 25, 57, 26, 58, 27, 59, 28, 60, 29, 61, 30, 62, 31, 63};
  alignas(64) static constexpr std::int16_t kOne[32] = {0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23,
                                                        8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31};
  const __m512i ilo = _mm512_load_si512(R == 2 ? kLo : kOne), ihi = _mm512_load_si512(kHi);
  __m512i a[R][J];
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
    for (int i = 0; i < R; ++i) a[i][t] = _mm512_setzero_si512();
  const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
  const int q0 = p0 / 2;
#pragma GCC unroll 2
  for (int k = 0; k < pc / 2; ++k) {
    if (more) {
#pragma GCC unroll 2
      for (int l = 0; l < R; ++l) __builtin_prefetch(share + 64 * (R * k + l), 0, kInt8PrefetchLocality);
    }
    const std::int8_t* w0 = w + static_cast<std::ptrdiff_t>(2 * k) * Out * 2;
    const std::int8_t* w1 = w0 + static_cast<std::ptrdiff_t>(Out) * 2;
    __m512i v[R];
    if constexpr (R == 2) {
      const __m512i l0 = _mm512_loadu_si512(w0), l1 = _mm512_loadu_si512(w1);
      v[0] = _mm512_permutex2var_epi16(l0, ilo, l1);
      v[1] = _mm512_permutex2var_epi16(l0, ihi, l1);
    } else {
      // The zero-masked form with every lane selected (GCC 12 warns on the unmasked one).
      const __m512i both =
          _mm512_maskz_inserti64x4(0xff, _mm512_castsi256_si512(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(w0))),
                                   _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w1)), 1);
      v[0] = _mm512_permutexvar_epi16(ilo, both);
    }
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      const __m512i xq = _mm512_set1_epi32(x.quads[t * Q + q0 + k]);
#pragma GCC unroll 2
      for (int i = 0; i < R; ++i) a[i][t] = _mm512_dpbusd_epi32(a[i][t], xq, v[i]);
    }
  }
  storeStripSumsAvx512<Out, J, R>(a, acc, r, p0 == 0);
}

/// The int8 product of 8-bit tokens (x.positive) with AVX-512 VNNI, In % 4 == 0: strips of
/// kInt8Strip pairs; in each, blocks of 32 rows (two 64-byte lines per quad of inputs), 2·J
/// int32 accumulators in zmm registers, each quad added by one vpdpbusd (half the instructions
/// of vpdpwssd for the same products). Rows left over: a block of 16, then the scalar rows.
template <int Out, int In, int J>
__attribute__((NAO_AVX512_TARGET, noinline)) void accumulateInt8QuadsAvx512(const std::int8_t* Wq,
                                                                             const QuantTokens<In, J>& x,
                                                                             std::int32_t* acc) {
  static_assert(In % 4 == 0 && In <= kInt8MaxIn && kInt8Strip % 2 == 0, "int8 quad kernel: In a multiple of 4");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 16 * 16;
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    int r = 0;
    for (; r + 32 <= kRows; r += 32) accumulateInt8QuadBlockAvx512<Out, In, J, 2>(Wq, x, acc, p0, pc, r);
    for (; r < kRows; r += 16) accumulateInt8QuadBlockAvx512<Out, In, J, 1>(Wq, x, acc, p0, pc, r);
  }
  if constexpr (Out % 16 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, x.pairs, acc, kRows);
}
#endif  // NAO_POLICY_HAVE_AVX2

/// Y = dequant(Wq) X + b (b may be null), then ReLU if kRelu, with int8 weights (see above).
/// The kernel is the one affineTokens uses; all give the same bits. Real-time safe: the
/// quantised tokens and accumulators live on the stack (at most 8 KB + 10 KB).
template <int Out, int In, int J, bool kRelu>
inline void affineTokensInt8(const std::int8_t* Wq, const float* sw, const float* b, const float* X, float* Y) {
  QuantTokens<In, J> x;
  alignas(64) std::int32_t acc[J * Out];
#if NAO_POLICY_HAVE_AVX2
  const PolicyKernel kernel = activePolicyKernel();
  if (kernel == PolicyKernel::kAvx512) {
    quantizeTokensInt8Avx512<In, J>(X, x);
    if constexpr (QuantTokens<In, J>::kQuads > 0) {
      if (x.positive)
        accumulateInt8QuadsAvx512<Out, In, J>(Wq, x, acc);
      else
        accumulateInt8Avx512<Out, In, J>(Wq, x.pairs, acc);
    } else {
      accumulateInt8Avx512<Out, In, J>(Wq, x.pairs, acc);
    }
    dequantizeTokensAvx512<Out, J, kRelu>(acc, sw, x.sx, b, Y);
    return;
  } else if (kernel == PolicyKernel::kAvx2) {
    quantizeTokensInt8<In, J>(X, x);
    accumulateInt8Avx2<Out, In, J>(Wq, x.pairs, acc);
  } else
#endif
  {
    quantizeTokensInt8<In, J>(X, x);
#if defined(__SSE2__)
    accumulateInt8Sse<Out, In, J>(Wq, x.pairs, acc);
#else
    accumulateRowsInt8Scalar<Out, In, J>(Wq, x.pairs, acc, 0);
#endif
  }
  dequantizeTokens<Out, J, kRelu>(acc, sw, x.sx, b, Y);
}

// ---------------------------------------------------------------------------------------------
// Window attention (policy.hpp windowAttention): one query's scores against every key of a
// ring, and the α-weighted sum of the values. Before these kernels the scores were Eigen's
// fixed-size dot of two Dh-vectors, one key at a time (about 12 % of a paper-model step); here
// the keys are the lanes, so 4 (SSE), 8 (AVX2) or 16 (AVX-512) scores come out of each pass over the query.
// The keys are stored transposed for that (PolicyWorkspace::KeyRing: column d holds dimension d
// of every key, rows padded to kKeyRowBlock).
//
// Bits: each lane computes one key's dot in exactly the order Eigen's fixed-size dot uses with
// 4-float packets (Eigen 3.4 redux_vec_unroller and predux<Packet4f>): the packet products
// q[4m..4m+3]·k[4m..4m+3] for m = 0..Dh/4−1 summed as a pairwise tree over m (for Dh/4 a power of
// two, halving is the same tree as bottom-up pairs), then the 4 lanes as (x0 + x2) + (x1 + x3).
// So the scores, and every bit after them, are those of the Eigen code they replace, with
// every kernel (tests/test_policy_kernels.cpp checks this against Eigen's dot on random data).
// The value sum is elementwise (o[d] += α·v[d], keys in the caller's order), the same at any
// width.

/// Rows of a key ring are padded to a multiple of this (the AVX-512 kernel's 16 lanes).
inline constexpr int kKeyRowBlock = 16;

/// True if the score kernels reproduce Eigen's dot of Dh floats bit for bit at this build's
/// packet width (else windowAttention keeps a plain loop over the transposed keys).
template <int Dh>
inline constexpr bool kWindowKernelExact =
    kPacketSize == 4 && Dh % 4 == 0 && Dh <= 64 && ((Dh / 4) & (Dh / 4 - 1)) == 0;

/// s[k] = dot(q, key k) · scale for keys k = 0 .. rows−1 (rows a multiple of kKeyRowBlock),
/// key k's dimension d at KT[d·NP + k]. Requires kWindowKernelExact<Dh>.
template <int Dh, int NP>
inline void windowScoresSse(const float* q, const float* KT, int rows, float scale, float* s) {
  using Eigen::internal::padd;
  using Eigen::internal::pmul;
  using Eigen::internal::ploadu;
  using Eigen::internal::pset1;
  static_assert(kWindowKernelExact<Dh>, "Eigen's dot order is reproduced for packets of 4 only");
  constexpr int P = 4, M = Dh / P;
  const Packet sc = pset1<Packet>(scale);
  for (int k0 = 0; k0 < rows; k0 += P) {
    Packet lane[P];
#pragma GCC unroll 4
    for (int l = 0; l < P; ++l) {
      Packet t[M];
#pragma GCC unroll 16
      for (int m = 0; m < M; ++m) t[m] = pmul(pset1<Packet>(q[m * P + l]), ploadu<Packet>(KT + (m * P + l) * NP + k0));
#pragma GCC unroll 4
      for (int w = 1; w < M; w *= 2)
#pragma GCC unroll 8
        for (int m = 0; m + w < M; m += 2 * w) t[m] = padd(t[m], t[m + w]);
      lane[l] = t[0];
    }
    Eigen::internal::pstoreu(s + k0, pmul(padd(padd(lane[0], lane[2]), padd(lane[1], lane[3])), sc));
  }
}

/// o[0 .. Dh) = Σ_m a[m] · v_m in m = 0 .. n·J−1 order (o starts at 0), v_m the value column of
/// age m / J, joint m % J: ring column ((slot − age + W) mod W)·J + j, at V + column·ld.
template <int Dh, int J, int W>
inline void windowValuesSse(const float* a, const float* V, int ld, int slot, int n, float* o) {
  using Eigen::internal::padd;
  using Eigen::internal::pmul;
  using Eigen::internal::ploadu;
  using Eigen::internal::pset1;
  constexpr int P = kPacketSize, NPk = Dh / P, Tail = Dh % P;
  Packet acc[NPk > 0 ? NPk : 1];
  float tail[Tail > 0 ? Tail : 1] = {};
  for (auto& x : acc) x = pset1<Packet>(0.0f);
  for (int age = 0; age < n; ++age) {
    const int base = ((slot - age + W) % W) * J;
    for (int j = 0; j < J; ++j) {
      const float aj = a[age * J + j];
      const Packet w = pset1<Packet>(aj);
      const float* v = V + static_cast<std::ptrdiff_t>(base + j) * ld;
#pragma GCC unroll 16
      for (int p = 0; p < NPk; ++p) acc[p] = padd(acc[p], pmul(w, ploadu<Packet>(v + p * P)));
      for (int d = 0; d < Tail; ++d) tail[d] += aj * v[NPk * P + d];
    }
  }
  for (int p = 0; p < NPk; ++p) Eigen::internal::pstoreu(o + p * P, acc[p]);
  for (int d = 0; d < Tail; ++d) o[NPk * P + d] = tail[d];
}

#if NAO_POLICY_HAVE_AVX2
/// windowScoresSse with 8 keys per pass (the same bits: the lanes are independent keys).
template <int Dh, int NP>
__attribute__((target("avx2"), noinline)) void windowScoresAvx2(const float* q, const float* KT, int rows, float scale,
                                                                 float* s) {
  static_assert(kWindowKernelExact<Dh>, "Eigen's dot order is reproduced for packets of 4 only");
  constexpr int P = 4, M = Dh / P;
  const __m256 sc = _mm256_set1_ps(scale);
  for (int k0 = 0; k0 < rows; k0 += 8) {
    __m256 lane[P];
#pragma GCC unroll 4
    for (int l = 0; l < P; ++l) {
      __m256 t[M];
#pragma GCC unroll 16
      for (int m = 0; m < M; ++m)
        t[m] = _mm256_mul_ps(_mm256_broadcast_ss(q + m * P + l), _mm256_loadu_ps(KT + (m * P + l) * NP + k0));
#pragma GCC unroll 4
      for (int w = 1; w < M; w *= 2)
#pragma GCC unroll 8
        for (int m = 0; m + w < M; m += 2 * w) t[m] = _mm256_add_ps(t[m], t[m + w]);
      lane[l] = t[0];
    }
    _mm256_storeu_ps(s + k0, _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(lane[0], lane[2]), _mm256_add_ps(lane[1], lane[3])), sc));
  }
}

/// windowValuesSse 8 dimensions at a time (Dh a multiple of 8; the same bits).
template <int Dh, int J, int W>
__attribute__((target("avx2"), noinline)) void windowValuesAvx2(const float* a, const float* V, int ld, int slot, int n,
                                                                 float* o) {
  static_assert(Dh % 8 == 0, "whole ymm registers of a head");
  __m256 acc[Dh / 8];
  for (auto& x : acc) x = _mm256_setzero_ps();
  for (int age = 0; age < n; ++age) {
    const int base = ((slot - age + W) % W) * J;
    for (int j = 0; j < J; ++j) {
      const __m256 w = _mm256_broadcast_ss(a + age * J + j);
      const float* v = V + static_cast<std::ptrdiff_t>(base + j) * ld;
#pragma GCC unroll 8
      for (int p = 0; p < Dh / 8; ++p) acc[p] = _mm256_add_ps(acc[p], _mm256_mul_ps(w, _mm256_loadu_ps(v + p * 8)));
    }
  }
  for (int p = 0; p < Dh / 8; ++p) _mm256_storeu_ps(o + p * 8, acc[p]);
}

/// One lane l of Eigen's 4-float packets for 16 keys and G queries: the pairwise tree over m of
/// q_g[4m + l]·k[4m + l], the broadcasts qb[g][m] = q_g[4m + l] given. Each key load serves
/// the G queries.
template <int M, int NP, int G>
__attribute__((NAO_AVX512_TARGET, always_inline)) inline void windowLanesAvx512(const __m512 (*qb)[M], const float* KTl,
                                                                               __m512* x) {
  __m512 t[G][M];
#pragma GCC unroll 16
  for (int m = 0; m < M; ++m) {
    const __m512 k = _mm512_loadu_ps(KTl + m * 4 * NP);
#pragma GCC unroll 4
    for (int g = 0; g < G; ++g) t[g][m] = _mm512_mul_ps(qb[g][m], k);
  }
#pragma GCC unroll 4
  for (int g = 0; g < G; ++g) {
#pragma GCC unroll 4
    for (int w = 1; w < M; w *= 2)
#pragma GCC unroll 8
      for (int m = 0; m + w < M; m += 2 * w) t[g][m] = _mm512_add_ps(t[g][m], t[g][m + w]);
    x[g] = t[g][0];
  }
}

/// windowScoresSse for G queries with 16 keys per pass (kAvx512; the same bits: the lanes are
/// independent keys): query g at q + g·q_stride, its scores at s + g·s_stride. Lane by lane
/// (0, 2, 1, 3) over every key block rather than block by block: a lane's G·M broadcasts stay in
/// registers across the blocks, so a block costs M key loads for G queries instead of 2·4·M
/// loads for one (loads, 2 per cycle here, bound the block-by-block form). The lanes meet in s
/// and x1 as (x0 + x2) + (x1 + x3), Eigen's order. G = 2 fits the registers (GCC 12 spills the
/// broadcasts of 3).
template <int Dh, int NP, int G>
__attribute__((NAO_AVX512_TARGET, noinline)) void windowScoresGroupAvx512(const float* q, int q_stride, const float* KT,
                                                                           int rows, float scale, float* s, int s_stride) {
  static_assert(kWindowKernelExact<Dh>, "Eigen's dot order is reproduced for packets of 4 only");
  static_assert(NP % 16 == 0, "key rows padded to whole zmm registers");
  constexpr int P = 4, M = Dh / P;
  constexpr int kOrder[P] = {0, 2, 1, 3};
  alignas(64) float x1[G][NP];
  __m512 qb[G][M];
#pragma GCC unroll 4
  for (int pass = 0; pass < P; ++pass) {
    const int l = kOrder[pass];
#pragma GCC unroll 4
    for (int g = 0; g < G; ++g)
#pragma GCC unroll 16
      for (int m = 0; m < M; ++m) qb[g][m] = _mm512_set1_ps(q[g * q_stride + m * P + l]);
    for (int k0 = 0; k0 < rows; k0 += 16) {
      __m512 x[G];
      windowLanesAvx512<M, NP, G>(qb, KT + l * NP + k0, x);
#pragma GCC unroll 4
      for (int g = 0; g < G; ++g) {
        float* sg = s + g * s_stride + k0;
        if (pass == 0) {
          _mm512_storeu_ps(sg, x[g]);
        } else if (pass == 1) {
          _mm512_storeu_ps(sg, _mm512_add_ps(_mm512_loadu_ps(sg), x[g]));
        } else if (pass == 2) {
          _mm512_store_ps(x1[g] + k0, x[g]);
        } else {
          const __m512 x13 = _mm512_add_ps(_mm512_load_ps(x1[g] + k0), x[g]);
          _mm512_storeu_ps(sg, _mm512_mul_ps(_mm512_add_ps(_mm512_loadu_ps(sg), x13), _mm512_set1_ps(scale)));
        }
      }
    }
  }
}

/// windowScoresSse with 16 keys per pass (kAvx512; the same bits).
template <int Dh, int NP>
inline void windowScoresAvx512(const float* q, const float* KT, int rows, float scale, float* s) {
  windowScoresGroupAvx512<Dh, NP, 1>(q, 0, KT, rows, scale, s, 0);
}

/// windowValuesSse for Q queries at once (kAvx512): query i's weights at a + i·a_stride, its
/// output at o + i·o_stride. Each query's sum runs over the keys in the same order (the same
/// bits); the Q independent chains of adds overlap instead of waiting on each other. One key per
/// iteration: unrolled over a tick's J keys, GCC kept half the Q·Dh/16 sums on the stack.
template <int Dh, int J, int W, int Q>
__attribute__((NAO_AVX512_TARGET, noinline)) void windowValuesAvx512(const float* a, int a_stride, const float* V, int ld,
                                                                      int slot, int n, float* o, int o_stride) {
  static_assert(Dh % 16 == 0, "whole zmm registers of a head");
  constexpr int NV = Dh / 16;
  __m512 acc[Q][NV];
  for (auto& row : acc)
    for (auto& x : row) x = _mm512_setzero_ps();
  for (int age = 0; age < n; ++age) {
    const float* vt = V + static_cast<std::ptrdiff_t>(((slot - age + W) % W) * J) * ld;
    const float* at = a + age * J;
#pragma GCC unroll 1
    for (int j = 0; j < J; ++j) {
      const float* v = vt + static_cast<std::ptrdiff_t>(j) * ld;
      __m512 vv[NV];
#pragma GCC unroll 8
      for (int p = 0; p < NV; ++p) vv[p] = _mm512_loadu_ps(v + p * 16);
#pragma GCC unroll 8
      for (int i = 0; i < Q; ++i) {
        const __m512 w = _mm512_set1_ps(at[i * a_stride + j]);
#pragma GCC unroll 8
        for (int p = 0; p < NV; ++p) acc[i][p] = _mm512_add_ps(acc[i][p], _mm512_mul_ps(w, vv[p]));
      }
    }
  }
  for (int i = 0; i < Q; ++i)
    for (int p = 0; p < NV; ++p) _mm512_storeu_ps(o + i * o_stride + p * 16, acc[i][p]);
}
#endif  // NAO_POLICY_HAVE_AVX2

/// The scores of windowScoresSse with the active kernel (the same bits with every kernel).
template <int Dh, int NP>
inline void windowScores(const float* q, const float* KT, int rows, float scale, float* s) {
#if NAO_POLICY_HAVE_AVX2
  const PolicyKernel kernel = activePolicyKernel();
  if constexpr (NP % 16 == 0) {
    if (kernel == PolicyKernel::kAvx512) {
      windowScoresAvx512<Dh, NP>(q, KT, rows, scale, s);
      return;
    }
  }
  if (policyKernelHasAvx2(kernel)) {
    windowScoresAvx2<Dh, NP>(q, KT, rows, scale, s);
    return;
  }
#endif
  windowScoresSse<Dh, NP>(q, KT, rows, scale, s);
}

/// windowScores for Q queries: query i at q + i·q_stride, its scores at s + i·s_stride (the same
/// bits as Q calls of windowScores). AVX-512 takes them two at a time (each key load serves both).
template <int Dh, int NP, int Q>
inline void windowScoresQueries(const float* q, int q_stride, const float* KT, int rows, float scale, float* s,
                                int s_stride) {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (NP % 16 == 0) {
    if (activePolicyKernel() == PolicyKernel::kAvx512) {
      int i = 0;
      for (; i + 2 <= Q; i += 2)
        windowScoresGroupAvx512<Dh, NP, 2>(q + i * q_stride, q_stride, KT, rows, scale, s + i * s_stride, s_stride);
      if (i < Q) windowScoresGroupAvx512<Dh, NP, 1>(q + i * q_stride, q_stride, KT, rows, scale, s + i * s_stride, s_stride);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) windowScores<Dh, NP>(q + i * q_stride, KT, rows, scale, s + i * s_stride);
}

/// The value sum of windowValuesSse with the active kernel (the same bits with every kernel).
template <int Dh, int J, int W>
inline void windowValues(const float* a, const float* V, int ld, int slot, int n, float* o) {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (Dh % 8 == 0) {
    if (policyKernelHasAvx2(activePolicyKernel())) {
      windowValuesAvx2<Dh, J, W>(a, V, ld, slot, n, o);
      return;
    }
  }
#endif
  windowValuesSse<Dh, J, W>(a, V, ld, slot, n, o);
}

// ---------------------------------------------------------------------------------------------
// The softmax's exponential (expShifted). glibc's expf was ~6 % of a step (16,000 calls: 8
// attention layers × 4 heads × 5 queries × 100 keys); this one runs in vector lanes. One
// definition in plain float multiplies and adds (never fused), evaluated identically by the
// scalar function and by every lane width, so the kernels keep giving the same bits:
//   x ← max(x, −87)            (NaN stays NaN: the comparison keeps x)
//   n = round-to-nearest-even(x · log2 e),  r = (x − n·C1) − n·C2   (C1 + C2 = ln 2, C1 exact in
//   8 bits: n·C1 is exact)
//   p = ((((p0 r + p1) r + p2) r + p3) r + p4) r + p5,  e = (p · r² + r) + 1
//   e^x = e · 2^n (exponent bits), and 0 for x < −87 (below 1.7e-38: a softmax weight that small
//   is 0 to float precision)
// Constants: the Cephes single-precision expf minimax polynomial on [−ln2/2, ln2/2]. Accuracy
// against std::exp: tests/test_policy_kernels.cpp.
namespace expconst {
inline constexpr float kLow = -87.0f;
inline constexpr float kLog2e = 1.44269504088896341f;
inline constexpr float kC1 = 0.693359375f;
inline constexpr float kC2 = -2.12194440e-4f;
inline constexpr float kP0 = 1.9875691500e-4f, kP1 = 1.3981999507e-3f, kP2 = 8.3334519073e-3f;
inline constexpr float kP3 = 4.1665795894e-2f, kP4 = 1.6666665459e-1f, kP5 = 5.0000001201e-1f;
}  // namespace expconst

/// The definition above for one float (the lanes' reference; x <= 0 expected: x − max score).
inline float expSoftmax(float x) noexcept {
  using namespace expconst;
  // Outside the domain (NaN, or above e^88 where the lanes' exponent bits wrap): keep the cast
  // below defined. NaN stays NaN as in the lanes.
  if (!(x <= 88.0f)) return x != x ? x : std::numeric_limits<float>::infinity();
  const bool flush = x < kLow;
  x = kLow > x ? kLow : x;
  const float fx = x * kLog2e;
  const auto n = static_cast<std::int32_t>(std::nearbyint(fx));
  const auto fn = static_cast<float>(n);
  float r = x - fn * kC1;
  r = r - fn * kC2;
  const float z = r * r;
  float p = kP0 * r;
  p = p + kP1;
  p = p * r;
  p = p + kP2;
  p = p * r;
  p = p + kP3;
  p = p * r;
  p = p + kP4;
  p = p * r;
  p = p + kP5;
  p = p * z;
  p = p + r;
  p = p + 1.0f;
  const std::uint32_t bits = static_cast<std::uint32_t>(n + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  const float e = p * scale;
  return flush ? 0.0f : e;
}

#if defined(__SSE2__)
/// expSoftmax in 4 lanes.
inline __m128 expSoftmaxSse(__m128 x) noexcept {
  using namespace expconst;
  const __m128 low = _mm_set1_ps(kLow);
  const __m128 keep = _mm_cmpnlt_ps(x, low);  // not (x < low): true for NaN too
  x = _mm_max_ps(low, x);                     // low > x ? low : x
  const __m128i n = _mm_cvtps_epi32(_mm_mul_ps(x, _mm_set1_ps(kLog2e)));
  const __m128 fn = _mm_cvtepi32_ps(n);
  __m128 r = _mm_sub_ps(x, _mm_mul_ps(fn, _mm_set1_ps(kC1)));
  r = _mm_sub_ps(r, _mm_mul_ps(fn, _mm_set1_ps(kC2)));
  const __m128 z = _mm_mul_ps(r, r);
  __m128 p = _mm_mul_ps(_mm_set1_ps(kP0), r);
  p = _mm_mul_ps(_mm_add_ps(p, _mm_set1_ps(kP1)), r);
  p = _mm_mul_ps(_mm_add_ps(p, _mm_set1_ps(kP2)), r);
  p = _mm_mul_ps(_mm_add_ps(p, _mm_set1_ps(kP3)), r);
  p = _mm_mul_ps(_mm_add_ps(p, _mm_set1_ps(kP4)), r);
  p = _mm_mul_ps(_mm_add_ps(p, _mm_set1_ps(kP5)), z);
  p = _mm_add_ps(_mm_add_ps(p, r), _mm_set1_ps(1.0f));
  const __m128 scale = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(n, _mm_set1_epi32(127)), 23));
  return _mm_and_ps(_mm_mul_ps(p, scale), keep);
}
#endif

#if NAO_POLICY_HAVE_AVX2
/// expSoftmax in 16 lanes (kAvx512). Fewer operations than the 4-lane form for the same bits:
/// max(low, x) is the clamp's select (NaN keeps x), vrndscaleps gives n as a float directly
/// (round to nearest even: the cvtps2dq/cvtdq2ps pair's value wherever |x·log2e| < 2³¹), and
/// vscalefps multiplies by 2ⁿ as the exponent bits did (both are one correctly rounded product
/// by an exact power of two). Equal to the former lanes on every float x <= 1 (checked
/// exhaustively; the softmax's arguments are <= 0): ~14 cycles a register here, not ~16.
__attribute__((NAO_AVX512_TARGET, always_inline)) inline __m512 expSoftmaxAvx512(__m512 x) noexcept {
  using namespace expconst;
  const __m512 low = _mm512_set1_ps(kLow);
  // Zero-masked forms with every lane selected, as in quantizeTokensInt8Avx512 (GCC 12 warns
  // on the unmasked ones).
  constexpr __mmask16 kAll = 0xffff;
  const __mmask16 keep = _mm512_cmp_ps_mask(x, low, _CMP_NLT_UQ);  // not (x < low): true for NaN
  x = _mm512_maskz_max_ps(kAll, low, x);                            // low > x ? low : x
  const __m512 fn = _mm512_maskz_roundscale_ps(kAll, _mm512_mul_ps(x, _mm512_set1_ps(kLog2e)),
                                               _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  __m512 r = _mm512_sub_ps(x, _mm512_mul_ps(fn, _mm512_set1_ps(kC1)));
  r = _mm512_sub_ps(r, _mm512_mul_ps(fn, _mm512_set1_ps(kC2)));
  const __m512 z = _mm512_mul_ps(r, r);
  __m512 p = _mm512_mul_ps(_mm512_set1_ps(kP0), r);
  p = _mm512_mul_ps(_mm512_add_ps(p, _mm512_set1_ps(kP1)), r);
  p = _mm512_mul_ps(_mm512_add_ps(p, _mm512_set1_ps(kP2)), r);
  p = _mm512_mul_ps(_mm512_add_ps(p, _mm512_set1_ps(kP3)), r);
  p = _mm512_mul_ps(_mm512_add_ps(p, _mm512_set1_ps(kP4)), r);
  p = _mm512_mul_ps(_mm512_add_ps(p, _mm512_set1_ps(kP5)), z);
  p = _mm512_add_ps(_mm512_add_ps(p, r), _mm512_set1_ps(1.0f));
  return _mm512_maskz_scalef_ps(keep, p, fn);
}

__attribute__((NAO_AVX512_TARGET, noinline)) inline void expShiftedAvx512(float* s, int count, float shift) noexcept {
  const __m512 sh = _mm512_set1_ps(shift);
  int m = 0;
  for (; m + 16 <= count; m += 16) _mm512_storeu_ps(s + m, expSoftmaxAvx512(_mm512_sub_ps(_mm512_loadu_ps(s + m), sh)));
  // The tail in masked lanes too (the scalar form, with its nearbyintf call, cost as much as
  // the rest: 100 keys leave 4).
  if (m < count) {
    const __mmask16 k = laneMask16(count - m);
    _mm512_mask_storeu_ps(s + m, k, expSoftmaxAvx512(_mm512_sub_ps(_mm512_maskz_loadu_ps(k, s + m), sh)));
  }
}
#endif

/// s[m] = expSoftmax(s[m] − shift) for m < count, in the widest lanes the active kernel has
/// (the same bits at any width).
inline void expShifted(float* s, int count, float shift) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if (activePolicyKernel() == PolicyKernel::kAvx512) {
    expShiftedAvx512(s, count, shift);
    return;
  }
#endif
  int m = 0;
#if defined(__SSE2__)
  const __m128 sh = _mm_set1_ps(shift);
  for (; m + 4 <= count; m += 4) _mm_storeu_ps(s + m, expSoftmaxSse(_mm_sub_ps(_mm_loadu_ps(s + m), sh)));
#endif
  for (; m < count; ++m) s[m] = expSoftmax(s[m] - shift);
}

// ---------------------------------------------------------------------------------------------
// The window attention's softmax (windowSoftmax): J queries' scores by ring row (raw, J rows of
// NP) → α by age (s, J rows of N: key age·J + j, newest tick first), with the age bias:
//   v = raw[i][((slot − age + W) mod W)·J + j] + bias[age];  max_i over v in key order;
//   e = expSoftmax(v − max_i);  sum_i = Σ e in key order (from 0);  α = e · (1 / sum_i)
// and α = 0 for the keys past n·J. Every kernel computes these same operations.

/// windowSoftmax in scalar code and expShifted's lanes (SSE2, AVX2).
template <int J, int W, int NP, int N>
inline void windowSoftmaxScalar(const float* raw, const float* bias, int slot, int n, float* s) noexcept {
  const int keys = n * J;
  float s_max[J], sum[J];
  for (int i = 0; i < J; ++i) {
    s_max[i] = -std::numeric_limits<float>::infinity();
    sum[i] = 0.0f;
  }
  for (int age = 0; age < n; ++age) {
    const int base = ((slot - age + W) % W) * J;
    for (int j = 0; j < J; ++j)
      for (int i = 0; i < J; ++i) {
        const float v = raw[i * NP + base + j] + bias[age];
        s[i * N + age * J + j] = v;
        s_max[i] = std::max(s_max[i], v);
      }
  }
  for (int i = 0; i < J; ++i) expShifted(s + i * N, keys, s_max[i]);
  for (int m = 0; m < keys; ++m)
    for (int i = 0; i < J; ++i) sum[i] += s[i * N + m];
  for (int i = 0; i < J; ++i) {
    const float inv = 1.0f / sum[i];
    for (int m = 0; m < keys; ++m) s[i * N + m] *= inv;
    for (int m = keys; m < N; ++m) s[i * N + m] = 0.0f;
  }
}

#if NAO_POLICY_HAVE_AVX2
/// windowSoftmax in zmm registers (kAvx512; J <= 16): a tick's J keys of a query in one masked
/// register for the bias and the maximum, the exponentials of all J rows in one loop with the
/// tail masked. The maximum runs in lanes: it is exact, so only a zero maximum could come out
/// with the other sign than the sequential std::max gives, and that case is redone in key
/// order (the same bits). The sums stay scalar, each row in key order. Paper model, per head:
/// ~1000 cycles against ~1500 for windowSoftmaxScalar with the same exponential lanes.
template <int J, int W, int NP, int N>
__attribute__((NAO_AVX512_TARGET, noinline)) void windowSoftmaxAvx512(const float* raw, const float* bias, int slot,
                                                                       int n, float* s) noexcept {
  static_assert(J <= 16, "a tick's keys in one zmm register");
  const int keys = n * J;
  constexpr __mmask16 kTick = laneMask16(J);
  const __m512 ninf = _mm512_set1_ps(-std::numeric_limits<float>::infinity());
  __m512 mx[J];
#pragma GCC unroll 16
  for (int i = 0; i < J; ++i) mx[i] = ninf;
  for (int age = 0; age < n; ++age) {
    const int base = ((slot - age + W) % W) * J;
    const __m512 b = _mm512_set1_ps(bias[age]);
#pragma GCC unroll 16
    for (int i = 0; i < J; ++i) {
      const __m512 v = _mm512_add_ps(_mm512_maskz_loadu_ps(kTick, raw + i * NP + base), b);
      _mm512_mask_storeu_ps(s + i * N + age * J, kTick, v);
      mx[i] = _mm512_mask_max_ps(mx[i], kTick, v, mx[i]);  // v > max ? v : max (NaN keeps max)
    }
  }
  float s_max[J];
#pragma GCC unroll 16
  for (int i = 0; i < J; ++i) {
    s_max[i] = foldLanesAvx512<true>(mx[i]);
    if (s_max[i] == 0.0f) {  // the sign of a zero maximum is the first zero's in key order
      float m = -std::numeric_limits<float>::infinity();
      for (int k = 0; k < keys; ++k) m = std::max(m, s[i * N + k]);
      s_max[i] = m;
    }
  }
  // The exponentials of the J rows 16 keys at a time (~16 cycles a register here, bound by
  // the operations' issue, not their latency).
  __m512 sh[J];
#pragma GCC unroll 16
  for (int i = 0; i < J; ++i) sh[i] = _mm512_set1_ps(s_max[i]);
  for (int m = 0; m < keys; m += 16) {
    const __mmask16 k = laneMask16(keys - m);
#pragma GCC unroll 16
    for (int i = 0; i < J; ++i)
      _mm512_mask_storeu_ps(s + i * N + m, k, expSoftmaxAvx512(_mm512_sub_ps(_mm512_maskz_loadu_ps(k, s + i * N + m), sh[i])));
  }
  // The sums stay scalar, in key order: ~250 cycles a head of the two add pipes (summing the
  // exponentials of the previous keys inside the loop above gained nothing).
  float sum[J];
#pragma GCC unroll 16
  for (int i = 0; i < J; ++i) sum[i] = 0.0f;
  for (int m = 0; m < keys; ++m)
#pragma GCC unroll 16
    for (int i = 0; i < J; ++i) sum[i] += s[i * N + m];
  __m512 inv[J];
#pragma GCC unroll 16
  for (int i = 0; i < J; ++i) inv[i] = _mm512_set1_ps(1.0f / sum[i]);
  for (int m = 0; m < N; m += 16) {
    const __mmask16 k = laneMask16(keys - m);  // α past the window's keys is 0
    const __mmask16 in_row = laneMask16(N - m);
#pragma GCC unroll 16
    for (int i = 0; i < J; ++i)
      _mm512_mask_storeu_ps(s + i * N + m, in_row, _mm512_maskz_mul_ps(k, _mm512_maskz_loadu_ps(k, s + i * N + m), inv[i]));
  }
}
#endif

/// windowSoftmax with the active kernel (the same bits with every kernel).
template <int J, int W, int NP, int N>
inline void windowSoftmax(const float* raw, const float* bias, int slot, int n, float* s) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (J <= 16) {
    if (activePolicyKernel() == PolicyKernel::kAvx512) {
      windowSoftmaxAvx512<J, W, NP, N>(raw, bias, slot, n, s);
      return;
    }
  }
#endif
  windowSoftmaxScalar<J, W, NP, N>(raw, bias, slot, n, s);
}

// ---------------------------------------------------------------------------------------------
// The norm-based attention score's vector norm (headSumNorm): ‖Σ_h a[h] f_h‖ over D floats, in
// one order at every lane width (so the kernels give the same bits):
//   c[d] = a[0] f_0[d] + a[1] f_1[d] + ... (left to right, the first term without a zero added)
//   part[l] = Σ c[d]² over d ≡ l (mod 16), d ascending, for the 16 lanes l
//   the lanes as a tree: part[l] += part[l + 8], then + 4, + 2, + 1; the norm is √part[0]
// Eigen's norm() summed in an order that depends on the packet width; this one is 16 lanes wide
// by definition, which SSE computes as 4 packets and AVX-512 as one register.

/// headSumNorm by its definition (any D; the reference of the vector forms).
template <int D, int H>
inline float headSumNormScalar(const float* a, const float* const* f) noexcept {
  float part[16] = {};
  for (int d = 0; d < D; ++d) {
    float c = a[0] * f[0][d];
    for (int h = 1; h < H; ++h) c = c + a[h] * f[h][d];
    part[d % 16] = part[d % 16] + c * c;
  }
  for (int w = 8; w >= 1; w /= 2)
    for (int l = 0; l < w; ++l) part[l] = part[l] + part[l + w];
  return std::sqrt(part[0]);
}

#if defined(__SSE2__)
/// headSumNorm with 4 packets of 4 lanes (D a multiple of 16).
template <int D, int H>
inline float headSumNormSse(const float* a, const float* const* f) noexcept {
  static_assert(D % 16 == 0, "whole groups of 16 lanes");
  __m128 part[4] = {_mm_setzero_ps(), _mm_setzero_ps(), _mm_setzero_ps(), _mm_setzero_ps()};
  __m128 ah[H];
  for (int h = 0; h < H; ++h) ah[h] = _mm_set1_ps(a[h]);
  for (int d0 = 0; d0 < D; d0 += 16)
#pragma GCC unroll 4
    for (int q = 0; q < 4; ++q) {
      __m128 c = _mm_mul_ps(ah[0], _mm_loadu_ps(f[0] + d0 + 4 * q));
      for (int h = 1; h < H; ++h) c = _mm_add_ps(c, _mm_mul_ps(ah[h], _mm_loadu_ps(f[h] + d0 + 4 * q)));
      part[q] = _mm_add_ps(part[q], _mm_mul_ps(c, c));
    }
  // Lanes l and l + 8: packets 0 + 2 and 1 + 3; then l + 4, l + 2, l + 1.
  __m128 x = _mm_add_ps(_mm_add_ps(part[0], part[2]), _mm_add_ps(part[1], part[3]));
  x = _mm_add_ps(x, _mm_movehl_ps(x, x));
  x = _mm_add_ss(x, _mm_shuffle_ps(x, x, 1));
  return std::sqrt(_mm_cvtss_f32(x));
}
#endif

#if NAO_POLICY_HAVE_AVX2
/// headSumNorm with one zmm register of 16 lanes (kAvx512; D a multiple of 16).
template <int D, int H>
__attribute__((NAO_AVX512_TARGET, noinline)) float headSumNormAvx512(const float* a, const float* const* f) noexcept {
  static_assert(D % 16 == 0, "whole groups of 16 lanes");
  __m512 part = _mm512_setzero_ps();
  __m512 ah[H];
  for (int h = 0; h < H; ++h) ah[h] = _mm512_set1_ps(a[h]);
#pragma GCC unroll 8
  for (int d0 = 0; d0 < D; d0 += 16) {
    __m512 c = _mm512_mul_ps(ah[0], _mm512_loadu_ps(f[0] + d0));
    for (int h = 1; h < H; ++h) c = _mm512_add_ps(c, _mm512_mul_ps(ah[h], _mm512_loadu_ps(f[h] + d0)));
    part = _mm512_add_ps(part, _mm512_mul_ps(c, c));
  }
  return std::sqrt(foldLanesAvx512<false>(part));  // lanes l + 8, l + 4, l + 2, l + 1
}
/// headSumNormAvx512 for Q coefficient sets over the same H vectors: out[i] = ‖Σ_h a[i·H + h]
/// f_h‖. The vectors are loaded once for all Q; each norm is the single kernel's, in its order
/// (the same bits), and the Q chains overlap instead of waiting on each other.
template <int D, int H, int Q>
__attribute__((NAO_AVX512_TARGET, noinline)) void headSumNormsAvx512(const float* a, const float* const* f,
                                                                     float* out) noexcept {
  static_assert(D % 16 == 0, "whole groups of 16 lanes");
  __m512 part[Q];
#pragma GCC unroll 8
  for (int i = 0; i < Q; ++i) part[i] = _mm512_setzero_ps();
#pragma GCC unroll 8
  for (int d0 = 0; d0 < D; d0 += 16) {
    __m512 fh[H];
#pragma GCC unroll 8
    for (int h = 0; h < H; ++h) fh[h] = _mm512_loadu_ps(f[h] + d0);
#pragma GCC unroll 8
    for (int i = 0; i < Q; ++i) {
      __m512 c = _mm512_mul_ps(_mm512_set1_ps(a[i * H]), fh[0]);
#pragma GCC unroll 8
      for (int h = 1; h < H; ++h) c = _mm512_add_ps(c, _mm512_mul_ps(_mm512_set1_ps(a[i * H + h]), fh[h]));
      part[i] = _mm512_add_ps(part[i], _mm512_mul_ps(c, c));
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < Q; ++i) out[i] = std::sqrt(foldLanesAvx512<false>(part[i]));
}
#endif

/// ‖Σ_h a[h] f_h‖ in the order above, with the active kernel's widest lanes.
template <int D, int H>
inline float headSumNorm(const float* a, const float* const* f) noexcept {
  if constexpr (D % 16 == 0) {
#if NAO_POLICY_HAVE_AVX2
    if (activePolicyKernel() == PolicyKernel::kAvx512) return headSumNormAvx512<D, H>(a, f);
#endif
#if defined(__SSE2__)
    return headSumNormSse<D, H>(a, f);
#endif
  }
  return headSumNormScalar<D, H>(a, f);
}

/// headSumNorm for Q coefficient sets (out[i] = ‖Σ_h a[i·H + h] f_h‖): the same bits as Q calls.
template <int D, int H, int Q>
inline void headSumNorms(const float* a, const float* const* f, float* out) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (D % 16 == 0) {
    if (activePolicyKernel() == PolicyKernel::kAvx512) {
      headSumNormsAvx512<D, H, Q>(a, f, out);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) out[i] = headSumNorm<D, H>(a + i * H, f);
}

/// windowValues for Q queries: query i's weights at a + i·a_stride, its output at
/// o + i·o_stride (the same bits as Q calls of windowValues).
template <int Dh, int J, int W, int Q>
inline void windowValuesQueries(const float* a, int a_stride, const float* V, int ld, int slot, int n, float* o,
                                int o_stride) {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (Dh % 16 == 0) {
    if (activePolicyKernel() == PolicyKernel::kAvx512) {
      windowValuesAvx512<Dh, J, W, Q>(a, a_stride, V, ld, slot, n, o, o_stride);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) windowValues<Dh, J, W>(a + i * a_stride, V, ld, slot, n, o + i * o_stride);
}

/// Y = W X + b (b may be null: zero), then ReLU if kRelu; every column an independent token.
/// Each Y(r, t) is b(r) + W(r,0) X(0,t) + W(r,1) X(1,t) + ... summed in that order, whatever
/// the kernel and packet width (bit-identical across kernels). W is read once. Real-time safe:
/// no temporaries, no Eigen GEMM (whose fixed-size blocking buffers land on the stack and whose
/// dynamic ones may allocate).
template <int Out, int In, int J, bool kRelu>
inline void affineTokens(const float* W, const float* b, const float* X, float* Y) {
#if NAO_POLICY_HAVE_AVX2
  const PolicyKernel kernel = activePolicyKernel();
  if (kernel == PolicyKernel::kAvx512) {
    affineTokensAvx512<Out, In, J, kRelu>(W, b, X, Y);
    return;
  }
  if (kernel == PolicyKernel::kAvx2) {
    affineTokensAvx2<Out, In, J, kRelu>(W, b, X, Y);
    return;
  }
#endif
  affineTokensSse<Out, In, J, kRelu>(W, b, X, Y);
}


// ---------------------------------------------------------------------------------------------
// Packed fp32 (docs/policy.md "Packed fp32 weights"): the same weights, the same bits, in the
// order the kernels read them. model.bin's matrices are column-major, so a block of 32 rows
// takes 128 bytes from each of a strip's 16 columns, 2 KB apart; that strided read comes out
// of L3 at ~49 GB/s against ~87 GB/s in address order (bench/results/policy.txt, BM_Layout_*).
// The packed copy stores each (strip, block) as 2 KB in a row:
//
//   P[((s·Out/32 + b)·16 + c)·32 + i] = W(32b + i, 16s + c)
//
// for Out a multiple of kPackBlock and In a multiple of kPackStrip (packedShape). Strip s is
// the 16·Out floats from s·16·Out, so columns c0 .. of W (c0 a multiple of 16) start at
// P + c0·Out, as in W itself (the per-head slices of Wo). Each kernel adds each row's terms in
// k order, multiply then add, strip by strip: the bits of affineTokens.

inline constexpr int kPackStrip = 16;  ///< columns per strip (kAvx2Strip)
inline constexpr int kPackBlock = 32;  ///< rows per block (the AVX-512 kernel's 2 zmm)
/// Floats ahead of the block being computed that each block prefetches (32 KB: measured on the
/// 512x512 product, BM_Layout_Packed; 1-4 strips ahead of the strided kernel gained nothing).
inline constexpr int kPackAhead = 8192;
/// Floats ahead that the AVX-512 kernel also prefetches into L1 (4 KB: two blocks), on top of the
/// L2 prefetch kPackAhead: BM_Policy_Packed p50 median 471 against 497 us, faster in 7 of 8
/// alternated pairs (bench/results/policy.txt, 2026-11-27; 8 KB was not clearly better).
inline constexpr int kPackNear = 1024;

/// True if a [Out, In] matrix has a packed copy.
constexpr bool packedShape(int out, int in) { return out % kPackBlock == 0 && in % kPackStrip == 0; }

/// Rows r+ro .. r+ro+2P−1 of one packed block (`blk`: its 32 rows × 16 columns, column stride
/// 32) += into Y, with the Eigen packet (P lanes) of kSse; xs[k][t] = X(k0 + k, t) broadcast.
template <int Out, int J>
inline void accumulatePackedSse(const float* blk, const Packet (&xs)[kPackStrip][J], float* Y, int r, int ro) {
  using Eigen::internal::padd;
  using Eigen::internal::pmul;
  using Eigen::internal::ploadu;
  using Eigen::internal::pstoreu;
  constexpr int P = kPacketSize;
  Packet acc0[J], acc1[J];
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t) {
    acc0[t] = ploadu<Packet>(Y + t * Out + r + ro);
    acc1[t] = ploadu<Packet>(Y + t * Out + r + ro + P);
  }
#pragma GCC unroll 4
  for (int k = 0; k < kPackStrip; ++k) {
    const Packet w0 = ploadu<Packet>(blk + kPackBlock * k + ro);
    const Packet w1 = ploadu<Packet>(blk + kPackBlock * k + ro + P);
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t) {
      acc0[t] = padd(acc0[t], pmul(w0, xs[k][t]));
      acc1[t] = padd(acc1[t], pmul(w1, xs[k][t]));
    }
  }
#pragma GCC unroll 8
  for (int t = 0; t < J; ++t) {
    pstoreu(Y + t * Out + r + ro, acc0[t]);
    pstoreu(Y + t * Out + r + ro + P, acc1[t]);
  }
}

/// affineTokens over the packed copy P with the kSse kernel's packets: per block, 2 packets
/// of rows at a time (2·J accumulators in registers), the strip's X broadcast once.
template <int Out, int In, int J, bool kRelu>
inline void affineTokensPackedSse(const float* P, const float* b, const float* X, float* Y) {
  static_assert(packedShape(Out, In), "no packed copy of this shape");
  static_assert(kPackBlock % (2 * kPacketSize) == 0, "a block is whole pairs of packets");
  initTokens<Out, J>(b, Y);
  const float* blk = P;
  for (int k0 = 0; k0 < In; k0 += kPackStrip) {
    Packet xs[kPackStrip][J];
    for (int k = 0; k < kPackStrip; ++k)
      for (int t = 0; t < J; ++t) xs[k][t] = Eigen::internal::pset1<Packet>(X[t * In + k0 + k]);
    for (int r = 0; r < Out; r += kPackBlock, blk += kPackBlock * kPackStrip) {
#if defined(__GNUC__)
      for (int line = 0; line < kPackBlock * kPackStrip; line += 16) __builtin_prefetch(blk + kPackAhead + line, 0, 2);
#endif
      for (int ro = 0; ro < kPackBlock; ro += 2 * kPacketSize) accumulatePackedSse<Out, J>(blk, xs, Y, r, ro);
    }
  }
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}

#if NAO_POLICY_HAVE_AVX2
/// affineTokens over the packed copy with 8-lane AVX2: per block, its two halves of 16 rows
/// (2·J ymm accumulators each).
template <int Out, int In, int J, bool kRelu>
__attribute__((target("avx2"), noinline)) void affineTokensPackedAvx2(const float* P, const float* b, const float* X,
                                                                       float* Y) {
  static_assert(packedShape(Out, In), "no packed copy of this shape");
  initTokens<Out, J>(b, Y);
  const float* blk = P;
  for (int k0 = 0; k0 < In; k0 += kPackStrip)
    for (int r = 0; r < Out; r += kPackBlock, blk += kPackBlock * kPackStrip)
      for (int h = 0; h < 2; ++h) {
        __m256 acc[2][J];
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
          for (int i = 0; i < 2; ++i) acc[i][t] = _mm256_loadu_ps(Y + t * Out + r + 16 * h + 8 * i);
#pragma GCC unroll 2
        for (int k = 0; k < kPackStrip; ++k) {
          // The block's 32 lines, one per (k, half).
          __builtin_prefetch(blk + kPackAhead + 16 * (2 * k + h), 0, 2);
          __m256 w[2];
#pragma GCC unroll 2
          for (int i = 0; i < 2; ++i) w[i] = _mm256_loadu_ps(blk + kPackBlock * k + 16 * h + 8 * i);
#pragma GCC unroll 8
          for (int t = 0; t < J; ++t) {
            const __m256 x = _mm256_broadcast_ss(X + t * In + k0 + k);
#pragma GCC unroll 2
            for (int i = 0; i < 2; ++i) acc[i][t] = _mm256_add_ps(acc[i][t], _mm256_mul_ps(w[i], x));
          }
        }
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
          for (int i = 0; i < 2; ++i) _mm256_storeu_ps(Y + t * Out + r + 16 * h + 8 * i, acc[i][t]);
      }
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}

/// affineTokens over the packed copy with AVX-512: one block of 32 rows in 2·J zmm
/// accumulators, its 2 KB read in address order.
template <int Out, int In, int J, bool kRelu>
__attribute__((NAO_AVX512_TARGET, noinline)) void affineTokensPackedAvx512(const float* P, const float* b,
                                                                            const float* X, float* Y) {
  static_assert(packedShape(Out, In), "no packed copy of this shape");
  initTokens<Out, J>(b, Y);
  const float* blk = P;
  for (int k0 = 0; k0 < In; k0 += kPackStrip)
    for (int r = 0; r < Out; r += kPackBlock, blk += kPackBlock * kPackStrip) {
      __m512 acc[2][J];
#pragma GCC unroll 8
      for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
        for (int i = 0; i < 2; ++i) acc[i][t] = _mm512_loadu_ps(Y + t * Out + r + 16 * i);
#pragma GCC unroll 2
      for (int k = 0; k < kPackStrip; ++k) {
#pragma GCC unroll 2
        for (int i = 0; i < 2; ++i) __builtin_prefetch(blk + kPackAhead + kPackBlock * k + 16 * i, 0, 2);
#pragma GCC unroll 2
        for (int i = 0; i < 2; ++i) __builtin_prefetch(blk + kPackNear + kPackBlock * k + 16 * i, 0, 3);
        __m512 w[2];
#pragma GCC unroll 2
        for (int i = 0; i < 2; ++i) w[i] = _mm512_loadu_ps(blk + kPackBlock * k + 16 * i);
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t) {
          const __m512 x = _mm512_set1_ps(X[t * In + k0 + k]);
#pragma GCC unroll 2
          for (int i = 0; i < 2; ++i) acc[i][t] = _mm512_add_ps(acc[i][t], _mm512_mul_ps(w[i], x));
        }
      }
#pragma GCC unroll 8
      for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
        for (int i = 0; i < 2; ++i) _mm512_storeu_ps(Y + t * Out + r + 16 * i, acc[i][t]);
    }
  if constexpr (kRelu) reluTokens<Out, J>(Y);
}
#endif  // NAO_POLICY_HAVE_AVX2

/// affineTokens over the packed copy P of W (packedShape(Out, In)), with the kernel in use:
/// the same bits as affineTokens over W. Real-time safe.
template <int Out, int In, int J, bool kRelu>
inline void affineTokensPacked(const float* P, const float* b, const float* X, float* Y) {
#if NAO_POLICY_HAVE_AVX2
  const PolicyKernel kernel = activePolicyKernel();
  if (kernel == PolicyKernel::kAvx512) {
    affineTokensPackedAvx512<Out, In, J, kRelu>(P, b, X, Y);
    return;
  }
  if (kernel == PolicyKernel::kAvx2) {
    affineTokensPackedAvx2<Out, In, J, kRelu>(P, b, X, Y);
    return;
  }
#endif
  affineTokensPackedSse<Out, In, J, kRelu>(P, b, X, Y);
}

}  // namespace detail
}  // namespace nao
