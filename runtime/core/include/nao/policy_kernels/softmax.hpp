// The window attention's softmax: its exponential (expSoftmax, expShifted) and the softmax
// over a window's keys with the age bias (windowSoftmax), with the kernel the caller passes
// (nao/policy_kernels/dispatch.hpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "nao/policy_kernels/lanes.hpp"

namespace nao {
namespace detail {

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

/// s[m] = expSoftmax(s[m] − shift) for m < count, in the widest lanes `kernel` has
/// (the same bits at any width).
inline void expShifted(PolicyKernel kernel, float* s, int count, float shift) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if (kernel == PolicyKernel::kAvx512) {
    expShiftedAvx512(s, count, shift);
    return;
  }
#endif
  (void)kernel;
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
inline void windowSoftmaxScalar(PolicyKernel kernel, const float* raw, const float* bias, int slot, int n,
                                float* s) noexcept {
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
  for (int i = 0; i < J; ++i) expShifted(kernel, s + i * N, keys, s_max[i]);
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

/// windowSoftmax with `kernel` (the same bits with every kernel).
template <int J, int W, int NP, int N>
inline void windowSoftmax(PolicyKernel kernel, const float* raw, const float* bias, int slot, int n,
                          float* s) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (J <= 16) {
    if (kernel == PolicyKernel::kAvx512) {
      windowSoftmaxAvx512<J, W, NP, N>(raw, bias, slot, n, s);
      return;
    }
  }
#endif
  windowSoftmaxScalar<J, W, NP, N>(kernel, raw, bias, slot, n, s);
}

}  // namespace detail
}  // namespace nao
