// The window attention's kernels: one query's scores against every key of a ring
// (windowScores) and the α-weighted sum of the values (windowValues), with the kernel the caller passes
// (nao/policy_kernels/dispatch.hpp).
#pragma once

#include <cstddef>

#include "nao/policy_kernels/lanes.hpp"

namespace nao {
namespace detail {

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

/// The scores of windowScoresSse with `kernel` (the same bits with every kernel).
template <int Dh, int NP>
inline void windowScores(PolicyKernel kernel, const float* q, const float* KT, int rows, float scale, float* s) {
#if NAO_POLICY_HAVE_AVX2
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
  (void)kernel;
  windowScoresSse<Dh, NP>(q, KT, rows, scale, s);
}

/// windowScores for Q queries: query i at q + i·q_stride, its scores at s + i·s_stride (the same
/// bits as Q calls of windowScores). AVX-512 takes them two at a time (each key load serves both).
template <int Dh, int NP, int Q>
inline void windowScoresQueries(PolicyKernel kernel, const float* q, int q_stride, const float* KT, int rows,
                                float scale, float* s, int s_stride) {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (NP % 16 == 0) {
    if (kernel == PolicyKernel::kAvx512) {
      int i = 0;
      for (; i + 2 <= Q; i += 2)
        windowScoresGroupAvx512<Dh, NP, 2>(q + i * q_stride, q_stride, KT, rows, scale, s + i * s_stride, s_stride);
      if (i < Q) windowScoresGroupAvx512<Dh, NP, 1>(q + i * q_stride, q_stride, KT, rows, scale, s + i * s_stride, s_stride);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) windowScores<Dh, NP>(kernel, q + i * q_stride, KT, rows, scale, s + i * s_stride);
}

/// The value sum of windowValuesSse with `kernel` (the same bits with every kernel).
template <int Dh, int J, int W>
inline void windowValues(PolicyKernel kernel, const float* a, const float* V, int ld, int slot, int n, float* o) {
  (void)kernel;
#if NAO_POLICY_HAVE_AVX2
  if constexpr (Dh % 8 == 0) {
    if (policyKernelHasAvx2(kernel)) {
      windowValuesAvx2<Dh, J, W>(a, V, ld, slot, n, o);
      return;
    }
  }
#endif
  windowValuesSse<Dh, J, W>(a, V, ld, slot, n, o);
}

/// windowValues for Q queries: query i's weights at a + i·a_stride, its output at
/// o + i·o_stride (the same bits as Q calls of windowValues).
template <int Dh, int J, int W, int Q>
inline void windowValuesQueries(PolicyKernel kernel, const float* a, int a_stride, const float* V, int ld, int slot,
                                int n, float* o, int o_stride) {
#if NAO_POLICY_HAVE_AVX2
  if constexpr (Dh % 16 == 0) {
    if (kernel == PolicyKernel::kAvx512) {
      windowValuesAvx512<Dh, J, W, Q>(a, a_stride, V, ld, slot, n, o, o_stride);
      return;
    }
  }
#endif
  for (int i = 0; i < Q; ++i) windowValues<Dh, J, W>(kernel, a + i * a_stride, V, ld, slot, n, o + i * o_stride);
}

}  // namespace detail
}  // namespace nao
