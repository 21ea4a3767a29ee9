// affineTokensInt8: the policy's matrix products with int8 weights (docs/policy.md "int8
// weights"), with the kernel the caller passes (nao/policy_kernels/dispatch.hpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "nao/policy_kernels/lanes.hpp"

#if defined(__SSE2__) && defined(__GNUC__)
#include <tmmintrin.h>
#endif

namespace nao {
namespace detail {

// ---------------------------------------------------------------------------------------------
// Reduced precision (docs/policy.md "int8 weights"): W as int8 with one scale per output row,
// the tokens quantised per column on the fly, products summed exactly in int32.
//
//   Wq  int8, pairs of input columns interleaved: byte (p·Out + r)·2 + e holds
//       round(W(r, 2p + e) / sw(r)), |·| <= 127 (quantizeMatrixInt8, codegen/src/quantize.cpp)
//   sw  float [Out], max_k |W(r, k)| / 127
//   X   one range per product, L levels: if no entry of X is negative (the FFN's inputs after
//       its ReLUs, 78 % of the paper model's weights) L = 127 (7 bits, unsigned), else
//       L = 32767 (16 bits, signed); each column t: xq = round(X(:, t) · L / max|X(:, t)|),
//       sx(t) = max|X(:, t)| / L (quantizeTokensInt8)
//   Y(r, t) = b(r) + float(Σ_k Wq(r, k) xq(k, t)) · (sw(r) · sx(t))
//
// 16-bit tokens: one pmaddwd multiplies a row's pair of int8 weights (sign-extended to int16) by
// the token's pair of xq (as int16) and adds the two products into an int32 lane (AVX-512 VNNI:
// vpdpwssd, the add too). 7-bit tokens: pmaddubsw multiplies four token bytes (unsigned) by a
// row's four weight bytes (signed), adding them in int16 pairs, pmaddwd by ones adds the pairs
// into an int32 lane (SSSE3, AVX2: twice pmaddwd's products per instruction, but with the
// widening pmaddwd the same multiplies per product; what it saves is the weights' widening and
// the instructions around the multiplies); AVX-512 VNNI: vpdpbusd, all in one. pmaddubsw
// saturates its int16 pair sums, which is why the unsigned range is 7 bits:
// |a0·w0 + a1·w1| <= 2 · 127 · 128 = 32512 < 32767 for any weight byte (the blob holds ±127) and
// any token byte in [0, 127], so no sum is ever clipped. 8-bit signed tokens everywhere measured
// 3.5x the action error (docs/policy.md). Integer sums are exact (|Σ| <= 512 · 127 · 32767 <
// 2^31 for In <= 512), so every kernel gives the same bits in any order; only the final
// conversion and two multiplies round (in one fixed order).

/// Largest In the int32 accumulators of the int8 kernels cannot overflow for.
inline constexpr int kInt8MaxIn = 512;

/// The J columns of one product quantised (quantizeTokensInt8 and its AVX-512 form fill pairs, sx
/// and positive, and quads when positive). Lives on the stack of affineTokensInt8.
template <int In, int J>
struct QuantTokens {
  static constexpr int kPairs = In / 2;
  static constexpr int kQuads = In % 4 == 0 ? In / 4 : 0;  ///< byte quads only when In % 4 == 0
  /// Lane p of column t: xq(2p, t) in the low int16, xq(2p + 1, t) in the high one.
  alignas(64) std::int32_t pairs[J * kPairs];
  /// Lane q of column t: the four bytes xq(4q .. 4q + 3, t) (the broadcast operand of pmaddubsw
  /// and vpdpbusd), when positive.
  alignas(64) std::int32_t quads[J * (kQuads > 0 ? kQuads : 1)];
  float sx[J];
  bool positive;  ///< xq in [0, 127] (no negative entry in X), else in [-32767, 32767]
};

/// The largest quantised magnitude of a product's range (127: see pmaddubsw above).
inline constexpr float int8TokenLevels(bool positive) { return positive ? 127.0f : 32767.0f; }

/// xq(k, t) of quantised tokens (tests and the scalar rows).
template <int In, int J>
inline int quantToken(const QuantTokens<In, J>& x, int k, int t) {
  const std::int32_t pair = x.pairs[t * (In / 2) + k / 2];
  return static_cast<std::int16_t>(k % 2 == 0 ? (pair & 0xffff) : (pair >> 16));
}

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
/// NaN as in the fp32 path; an all-zero column gets sx = 0. Fills quads when positive.
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
    auto* bytes = reinterpret_cast<std::uint8_t*>(x.quads + t * QuantTokens<In, J>::kQuads);
    const bool bytes_too = QuantTokens<In, J>::kQuads > 0 && x.positive;
    const float m = mx[t];
    // q = round-to-nearest-even(x · hi / m), in [lo, hi] (the product may round up past hi:
    // clamped). cvtps2dq rounds like nearbyint in the default rounding mode. m below ~1e-36
    // overflows hi / m: the column is zero to within 1e-36 of every input (its products are
    // below what any output can resolve), quantised as zero.
    const float inv = hi / m;
    if (poison[t] != 0.0f || m == 0.0f || !(inv <= std::numeric_limits<float>::max())) {  // NaN != 0
      for (int p = 0; p < In / 2; ++p) out[p] = 0;
      if (bytes_too)
        for (int q = 0; q < QuantTokens<In, J>::kQuads; ++q) x.quads[t * QuantTokens<In, J>::kQuads + q] = 0;
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
        const __m128i w = _mm_packs_epi32(a, b);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k / 2), w);
        // In [0, 127] when positive: the same eight values as bytes.
        if (bytes_too) _mm_storel_epi64(reinterpret_cast<__m128i*>(bytes + k), _mm_packus_epi16(w, w));
      }
    }
#endif
    quantizePairsScalar(xc, out, k, In, inv, lo, hi);
    if (bytes_too)
      for (int i = k; i < In; ++i) bytes[i] = static_cast<std::uint8_t>(quantToken(x, i, t));
    x.sx[t] = m / hi;
  }
}

#if NAO_POLICY_HAVE_AVX2
/// quantizeTokensInt8 with 16 lanes (kAvx512): the same maxima, tests, products, roundings and
/// clamps, so the same pairs and scales and (7-bit products) the same byte quads.
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
        // The low byte of each lane: xq in [0, 127] as an unsigned byte.
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
#if defined(__GNUC__) && !defined(__AVX__)
/// Where the int8 kernels may add a product into its accumulator by an explicit legacy-encoded
/// paddd (GCC otherwise added into the product and copied it back, and spilled accumulators):
/// not in a build whose code is VEX-encoded (-mavx), where it would mix encodings.
inline constexpr bool kInt8LegacyAdd = true;
#else
inline constexpr bool kInt8LegacyAdd = false;
#endif

/// acc += p (int32 lanes), by a paddd into acc itself when kAsm && kInt8LegacyAdd.
template <bool kAsm>
__attribute__((always_inline)) inline void addInt8Sums(__m128i& acc, __m128i p) {
#if defined(__GNUC__)
  if constexpr (kAsm && kInt8LegacyAdd) {
    __asm__("paddd %1, %0" : "+x"(acc) : "x"(p));
    return;
  }
#endif
  acc = _mm_add_epi32(acc, p);
}

/// The int8 product with SSE2 (the NAO's Atom and every x86-64): strips of kInt8Strip pairs;
/// in each, the strip's token pairs broadcast once, then blocks of 8 rows with 2·J int32
/// accumulators in xmm registers (each sum added in place: see kInt8LegacyAdd).
template <int Out, int In, int J>
inline void accumulateInt8Sse(const std::int8_t* Wq, const std::int32_t* xp, std::int32_t* acc) {
  static_assert(In % 2 == 0 && In <= kInt8MaxIn, "int8 kernel: In even and at most kInt8MaxIn");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 8 * 8;
  __m128i xs[kInt8Strip][J];
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    for (int i = 0; i < pc; ++i)
      for (int t = 0; t < J; ++t) xs[i][t] = _mm_set1_epi32(xp[t * P + p0 + i]);
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
#pragma GCC unroll 1
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
          addInt8Sums<true>(a0[t], _mm_madd_epi16(xs[i][t], lo));
          addInt8Sums<true>(a1[t], _mm_madd_epi16(xs[i][t], hi));
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

#if defined(__SSE2__) && defined(__GNUC__)
// The 7-bit kernels' instruction set: SSSE3 (pmaddubsw). The robot build's -march=silvermont has
// it; an x86-64 build without -march tags the kernels and asks the CPU at each call: one load
// and bit test of the compiler runtime's cpu model, which the binders initialise
// (bestPolicyKernel), so nothing of ours keeps state. Every x86-64 CPU since 2006 has it; one
// without runs the pmaddwd kernel instead, the same bits.
#define NAO_INT8_SSSE3_TARGET target("ssse3")
#if defined(__SSSE3__)
inline bool int8HaveSsse3() noexcept { return true; }
#else
inline bool int8HaveSsse3() noexcept { return __builtin_cpu_supports("ssse3") != 0; }
#endif

/// xs[k][t] = the token quad q0 + k of column t in every lane (q0 = p0 / 2, k < pc / 2).
template <int In, int J>
__attribute__((NAO_INT8_SSSE3_TARGET, always_inline)) inline void broadcastStripQuadsSsse3(
    const QuantTokens<In, J>& x, int p0, int pc, __m128i (*xs)[J]) {
  constexpr int Q = QuantTokens<In, J>::kQuads;
  for (int k = 0; k < pc / 2; ++k)
    for (int t = 0; t < J; ++t) xs[k][t] = _mm_set1_epi32(x.quads[t * Q + p0 / 2 + k]);
}

/// Rows r .. r+4R-1 (R = 1 or 2) of the product of 7-bit tokens over pairs p0 .. p0+pc-1 (one
/// strip, pc even): per quad of inputs, the rows' bytes of pairs 2k and 2k+1 interleaved by
/// words (punpck{l,h}wd) give each row's four consecutive weights in one int32 lane; pmaddubsw
/// (token bytes unsigned, weights signed; exact, see above) then pmaddwd by ones makes each lane
/// one row's sum. `xs[k][t]`: the strip's token quads, broadcast; `share`: this block's pc·8R
/// bytes of the next strip to prefetch, or null. kLegacyAdd (only where no VEX code surrounds
/// it, see kInt8LegacyAdd): each sum added by a paddd into its accumulator; GCC added the
/// accumulator into the product and copied it back (one movdqa per multiply-add, a fifth of the
/// loop's instructions on the two-wide Atom) and, with 2·J accumulators, spilled a third of them.
template <int Out, int In, int J, int R, bool kLegacyAdd>
__attribute__((NAO_INT8_SSSE3_TARGET, always_inline)) inline void accumulateInt8QuadBlockSsse3(
    const std::int8_t* Wq, const __m128i (*xs)[J], std::int32_t* acc, int p0, int pc, int r,
    const std::int8_t* share) {
  static_assert(R == 1 || R == 2, "blocks of 4 or 8 rows");
  const __m128i ones = _mm_set1_epi16(1);
  __m128i a[R][J];
  for (int i = 0; i < R; ++i)
    for (int t = 0; t < J; ++t) a[i][t] = _mm_setzero_si128();
  const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
  // Not unrolled: unrolled, GCC hoisted the multiplies of several quads and spilled their results.
#pragma GCC unroll 1
  for (int k = 0; k < pc / 2; ++k) {
#if defined(__GNUC__)
    if (share != nullptr && (k & (4 / R - 1)) == 0) __builtin_prefetch(share + 16 * R * k, 0, kInt8PrefetchLocality);
#endif
    const std::int8_t* w0 = w + static_cast<std::ptrdiff_t>(2 * k) * Out * 2;
    const std::int8_t* w1 = w0 + static_cast<std::ptrdiff_t>(Out) * 2;
    __m128i v[R];
    if constexpr (R == 2) {
      const __m128i l0 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(w0));
      const __m128i l1 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(w1));
      v[0] = _mm_unpacklo_epi16(l0, l1);  // rows r..r+3, inputs 4k'..4k'+3 each
      v[1] = _mm_unpackhi_epi16(l0, l1);  // rows r+4..r+7
    } else {
      v[0] = _mm_unpacklo_epi16(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(w0)),
                                _mm_loadl_epi64(reinterpret_cast<const __m128i*>(w1)));
    }
#pragma GCC unroll 8
    for (int t = 0; t < J; ++t)
#pragma GCC unroll 2
      for (int i = 0; i < R; ++i) {
        addInt8Sums<kLegacyAdd>(a[i][t], _mm_madd_epi16(_mm_maddubs_epi16(xs[k][t], v[i]), ones));
      }
  }
  for (int i = 0; i < R; ++i)
    for (int t = 0; t < J; ++t) {
      auto* y = reinterpret_cast<__m128i*>(acc + t * Out + r + 4 * i);
      _mm_storeu_si128(y, p0 == 0 ? a[i][t] : _mm_add_epi32(_mm_loadu_si128(y), a[i][t]));
    }
}

/// The int8 product of 7-bit tokens (x.positive) with SSSE3 (the NAO's Atom), In % 4 == 0:
/// strips of kInt8Strip pairs; in each, blocks of 8 rows with 2·J int32 accumulators in xmm
/// registers, then one of 4 rows. Rows left over: the scalar rows. The strip's token quads are broadcast once into
/// `xs` (each block then loads them: without it GCC spilled half the accumulators).
template <int Out, int In, int J>
__attribute__((NAO_INT8_SSSE3_TARGET, noinline)) void accumulateInt8QuadsSsse3(const std::int8_t* Wq,
                                                                               const QuantTokens<In, J>& x,
                                                                               std::int32_t* acc) {
  static_assert(In % 4 == 0 && In <= kInt8MaxIn && kInt8Strip % 2 == 0, "int8 quad kernel: In a multiple of 4");
  constexpr int P = In / 2;
  constexpr int kRows = Out / 4 * 4;
  __m128i xs[kInt8Strip / 2][J];
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    const bool more = p0 + pc < P;  // the next strip of this matrix, as in accumulateInt8Sse
    const std::int8_t* next = Wq + static_cast<std::ptrdiff_t>(p0 + pc) * Out * 2;
    broadcastStripQuadsSsse3<In, J>(x, p0, pc, xs);
    int r = 0;
    for (; r + 8 <= kRows; r += 8)
      accumulateInt8QuadBlockSsse3<Out, In, J, 2, true>(Wq, xs, acc, p0, pc, r,
                                                        more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr);
    for (; r < kRows; r += 4)
      accumulateInt8QuadBlockSsse3<Out, In, J, 1, true>(Wq, xs, acc, p0, pc, r,
                                                        more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr);
  }
  if constexpr (Out % 4 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, x.pairs, acc, kRows);
}
#endif  // __SSE2__ && __GNUC__

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

/// The int8 product of 7-bit tokens (x.positive) with AVX2, In % 4 == 0: strips of kInt8Strip
/// pairs; in each, blocks of 16 rows (one 32-byte line of each pair), each quad of inputs
/// interleaved and multiplied as in accumulateInt8QuadBlock8Ssse3 with 2·J int32 accumulators
/// in ymm registers (vpunpck{l,h}wd work in 128-bit lanes: rows 0-3 and 8-11 in one register,
/// 4-7 and 12-15 in the other, put in order at the store). Rows left over: blocks of 4 (the
/// SSSE3 ones), then the scalar rows.
template <int Out, int In, int J>
__attribute__((target("avx2"), noinline)) void accumulateInt8QuadsAvx2(const std::int8_t* Wq, const QuantTokens<In, J>& x,
                                                                         std::int32_t* acc) {
  static_assert(In % 4 == 0 && In <= kInt8MaxIn && kInt8Strip % 2 == 0, "int8 quad kernel: In a multiple of 4");
  constexpr int P = In / 2, Q = In / 4;
  constexpr int kRows16 = Out / 16 * 16, kRows = Out / 4 * 4;
  const __m256i ones = _mm256_set1_epi16(1);
  for (int p0 = 0; p0 < P; p0 += kInt8Strip) {
    const int pc = std::min(kInt8Strip, P - p0);
    const bool more = p0 + pc < P;
    const std::int8_t* next = Wq + static_cast<std::ptrdiff_t>(p0 + pc) * Out * 2;
    const int q0 = p0 / 2;
    for (int r = 0; r < kRows16; r += 16) {
      __m256i a0[J], a1[J];
      for (int t = 0; t < J; ++t) a0[t] = a1[t] = _mm256_setzero_si256();
      const std::int8_t* w = Wq + static_cast<std::ptrdiff_t>(p0) * Out * 2 + r * 2;
      const std::int8_t* share = more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr;  // pc·32 bytes
      // Not unrolled: unrolled, GCC stored the accumulators to the stack every other quad.
#pragma GCC unroll 1
      for (int k = 0; k < pc / 2; ++k) {
        if (more) __builtin_prefetch(share + 64 * k, 0, kInt8PrefetchLocality);
        const std::int8_t* w0 = w + static_cast<std::ptrdiff_t>(2 * k) * Out * 2;
        const __m256i l0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w0));
        const __m256i l1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w0 + static_cast<std::ptrdiff_t>(Out) * 2));
        const __m256i lo = _mm256_unpacklo_epi16(l0, l1);  // rows 0-3 | 8-11
        const __m256i hi = _mm256_unpackhi_epi16(l0, l1);  // rows 4-7 | 12-15
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t) {
          const __m256i xb = _mm256_set1_epi32(x.quads[t * Q + q0 + k]);
          a0[t] = _mm256_add_epi32(a0[t], _mm256_madd_epi16(_mm256_maddubs_epi16(xb, lo), ones));
          a1[t] = _mm256_add_epi32(a1[t], _mm256_madd_epi16(_mm256_maddubs_epi16(xb, hi), ones));
        }
      }
      for (int t = 0; t < J; ++t) {
        const __m256i y0 = _mm256_permute2x128_si256(a0[t], a1[t], 0x20);  // rows 0-7
        const __m256i y1 = _mm256_permute2x128_si256(a0[t], a1[t], 0x31);  // rows 8-15
        auto* d0 = reinterpret_cast<__m256i*>(acc + t * Out + r);
        auto* d1 = reinterpret_cast<__m256i*>(acc + t * Out + r + 8);
        _mm256_storeu_si256(d0, p0 == 0 ? y0 : _mm256_add_epi32(_mm256_loadu_si256(d0), y0));
        _mm256_storeu_si256(d1, p0 == 0 ? y1 : _mm256_add_epi32(_mm256_loadu_si256(d1), y1));
      }
    }
    if constexpr (kRows > kRows16) {
      __m128i xs[kInt8Strip / 2][J];
      broadcastStripQuadsSsse3<In, J>(x, p0, pc, xs);
      for (int r = kRows16; r < kRows; r += 4)
        accumulateInt8QuadBlockSsse3<Out, In, J, 1, false>(Wq, xs, acc, p0, pc, r,
                                                           more ? next + static_cast<std::ptrdiff_t>(r) * 2 * pc : nullptr);
    }
  }
  if constexpr (Out % 4 != 0) accumulateRowsInt8Scalar<Out, In, J>(Wq, x.pairs, acc, kRows);
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
/// `kernel` as for affineTokens; all give the same bits. Real-time safe: the
/// quantised tokens and accumulators live on the stack (at most 8 KB + 10 KB).
template <int Out, int In, int J, bool kRelu>
inline void affineTokensInt8(PolicyKernel kernel, const std::int8_t* Wq, const float* sw, const float* b,
                             const float* X, float* Y) {
  QuantTokens<In, J> x;
  alignas(64) std::int32_t acc[J * Out];
#if NAO_POLICY_HAVE_AVX2
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
    if constexpr (QuantTokens<In, J>::kQuads > 0) {
      if (x.positive)
        accumulateInt8QuadsAvx2<Out, In, J>(Wq, x, acc);
      else
        accumulateInt8Avx2<Out, In, J>(Wq, x.pairs, acc);
    } else {
      accumulateInt8Avx2<Out, In, J>(Wq, x.pairs, acc);
    }
  } else
#endif
  {
    (void)kernel;
    quantizeTokensInt8<In, J>(X, x);
#if defined(__SSE2__) && defined(__GNUC__)
    if constexpr (QuantTokens<In, J>::kQuads > 0) {
      if (x.positive && int8HaveSsse3())
        accumulateInt8QuadsSsse3<Out, In, J>(Wq, x, acc);
      else
        accumulateInt8Sse<Out, In, J>(Wq, x.pairs, acc);
    } else {
      accumulateInt8Sse<Out, In, J>(Wq, x.pairs, acc);
    }
#elif defined(__SSE2__)
    accumulateInt8Sse<Out, In, J>(Wq, x.pairs, acc);
#else
    accumulateRowsInt8Scalar<Out, In, J>(Wq, x.pairs, acc, 0);
#endif
  }
  dequantizeTokens<Out, J, kRelu>(acc, sw, x.sx, b, Y);
}

}  // namespace detail
}  // namespace nao
