// headSumNorm: the norm-based attention score's vector norm, with the kernel the caller passes
// (nao/policy_kernels/dispatch.hpp).
#pragma once

#include <cmath>

#include "nao/policy_kernels/lanes.hpp"

namespace nao {
namespace detail {

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

/// ‖Σ_h a[h] f_h‖ in the order above, with the widest lanes of `kernel`.
template <int D, int H>
inline float headSumNorm(PolicyKernel kernel, const float* a, const float* const* f) noexcept {
  (void)kernel;
  if constexpr (D % 16 == 0) {
#if NAO_POLICY_HAVE_AVX2
    if (kernel == PolicyKernel::kAvx512) return headSumNormAvx512<D, H>(a, f);
#endif
#if defined(__SSE2__)
    return headSumNormSse<D, H>(a, f);
#endif
  }
  return headSumNormScalar<D, H>(a, f);
}

/// headSumNorm for Q coefficient sets (out[i] = ‖Σ_h a[i·H + h] f_h‖): the same bits as Q calls.
template <int D, int H, int Q>
inline void headSumNorms(PolicyKernel kernel, const float* a, const float* const* f, float* out) noexcept {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (D % 16 == 0) {
    if (kernel == PolicyKernel::kAvx512) {
      headSumNormsAvx512<D, H, Q>(a, f, out);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) out[i] = headSumNorm<D, H>(kernel, a + i * H, f);
}

}  // namespace detail
}  // namespace nao
