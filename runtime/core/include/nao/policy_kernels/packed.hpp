// affineTokensPacked: affineTokens over the packed fp32 copy of W (docs/policy.md "Packed fp32
// weights"), with the kernel the caller passes (nao/policy_kernels/dispatch.hpp).
#pragma once

#include "nao/policy_kernels/affine.hpp"
#include "nao/policy_kernels/lanes.hpp"

namespace nao {
namespace detail {

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

/// affineTokens over the packed copy P of W (packedShape(Out, In)), with `kernel`:
/// the same bits as affineTokens over W. Real-time safe.
template <int Out, int In, int J, bool kRelu>
inline void affineTokensPacked(PolicyKernel kernel, const float* P, const float* b, const float* X, float* Y) {
#if NAO_POLICY_HAVE_AVX2
  if (kernel == PolicyKernel::kAvx512) {
    affineTokensPackedAvx512<Out, In, J, kRelu>(P, b, X, Y);
    return;
  }
  if (kernel == PolicyKernel::kAvx2) {
    affineTokensPackedAvx2<Out, In, J, kRelu>(P, b, X, Y);
    return;
  }
#endif
  (void)kernel;
  affineTokensPackedSse<Out, In, J, kRelu>(P, b, X, Y);
}

}  // namespace detail
}  // namespace nao
