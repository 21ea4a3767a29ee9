// The vector registers the policy kernel families share: Eigen's packet at the build's
// baseline width (the kSse kernels) and the AVX-512 kernels' lane masks and folds.
#pragma once

#include <Eigen/Core>

#include "nao/policy_kernels/dispatch.hpp"

namespace nao {
namespace detail {

using Packet = Eigen::internal::packet_traits<float>::type;
inline constexpr int kPacketSize = Eigen::internal::packet_traits<float>::size;

#if NAO_POLICY_HAVE_AVX2
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
#endif  // NAO_POLICY_HAVE_AVX2

}  // namespace detail
}  // namespace nao
