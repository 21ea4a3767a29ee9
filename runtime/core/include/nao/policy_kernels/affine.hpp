// affineTokens: Y = W X + b over J token columns, W in model.bin's column-major layout, with
// the kSse, kAvx2 and kAvx512 kernels (nao/policy_kernels/dispatch.hpp).
//
// All compute every Y(r, t) as b(r) + W(r,0) X(0,t) + W(r,1) X(1,t) + ... in k order, one
// rounded multiply then one rounded add per term (never fused: -ffp-contract=off, and the AVX2
// functions are compiled without the FMA ISA), so the two give bit-identical results; the lane
// width only changes how many rows are computed at once (tests/test_policy_kernels.cpp).
#pragma once

#include <algorithm>
#include <cstddef>

#include "nao/policy_kernels/lanes.hpp"

namespace nao {
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

/// Y = W X + b (b may be null: zero), then ReLU if kRelu; every column an independent token.
/// Each Y(r, t) is b(r) + W(r,0) X(0,t) + W(r,1) X(1,t) + ... summed in that order, whatever
/// the kernel and packet width (bit-identical across kernels). W is read once. Real-time safe:
/// no temporaries, no Eigen GEMM (whose fixed-size blocking buffers land on the stack and whose
/// dynamic ones may allocate).
template <int Out, int In, int J, bool kRelu>
inline void affineTokens(PolicyKernel kernel, const float* W, const float* b, const float* X, float* Y) {
#if NAO_POLICY_HAVE_AVX2
  if (kernel == PolicyKernel::kAvx512) {
    affineTokensAvx512<Out, In, J, kRelu>(W, b, X, Y);
    return;
  }
  if (kernel == PolicyKernel::kAvx2) {
    affineTokensAvx2<Out, In, J, kRelu>(W, b, X, Y);
    return;
  }
#endif
  (void)kernel;
  affineTokensSse<Out, In, J, kRelu>(W, b, X, Y);
}

}  // namespace detail
}  // namespace nao
