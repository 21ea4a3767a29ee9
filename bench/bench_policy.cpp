// Policy inference latency on the paper configuration (the committed models/default.bin):
//   BM_Policy_StaticEigen  the runtime's fixed-size float stepPolicy (nao/policy.hpp) with the
//                          kernel benchPolicyKernel picks (NAO_POLICY_KERNEL, CPU; the label names it)
//   BM_Policy_StaticEigen_SSE / _AVX2  the same with the kernel forced (nao/policy_kernels.hpp);
//                          _AVX2 is skipped with a message on a CPU without AVX2
//   BM_Policy_Int8 / _SSE / _AVX2  the same with the attention and FFN matrices in int8
//                          (nao/quantize.hpp: quantised from the fp32 model at set-up, the bytes
//                          nao_codegen --precision int8 compiles in)
//   BM_Policy_Packed / _SSE / _AVX2 / _AVX512  fp32 with the attention and FFN matrices packed
//                          in the kernels' block order (nao/quantize.hpp packModelFp32, at set-up):
//                          the same bits (counter same_bits), read in address order
//   BM_Policy_*_AVX512     the same with the AVX-512 kernels (skipped without AVX-512 F/BW/VNNI)
//   BM_WeightStream        the physical limit: one read of the same weight bytes, 64-byte
//                          aligned as nao_rt holds them (paperWeights), by the fastest of the
//                          candidate reads timed in the same run (fastestRead; the label names
//                          it), i.e. weight bytes / single-core read bandwidth
//   BM_Policy_Cold_* / BM_Policy_Packed_Cold_* / BM_Policy_Int8_Cold_* / BM_WeightStream_Cold
//                          the same after evicting the caches before every iteration (untimed):
//                          the weights come from DRAM
//   BM_MulAddFloor         the arithmetic limit: as many separately rounded multiply-adds as a
//                          step does (matrix weights × 5 tokens), from registers, widest width
//   BM_WeightStream_Eigen  the same bytes read by Eigen's vectorised sum (the limit quoted before
//                          2026-11-26: ~2-2.5x the fastest aligned read on this machine)
//   BM_Layout_Strided / _Packed  24 MB of 512x512 matrices x 5 tokens with the AVX-512 product in
//                          model.bin's column-major layout and repacked block by block (below),
//                          each layout's matrices one aligned block
//   BM_Int8Layout_Pairs / _Quads  4 MB of int8 512x512 matrices x 5 7-bit tokens with vpdpbusd:
//                          the blob's pairs interleaved by vpermt2w (the runtime's kernel), and a
//                          candidate layout with each row's 4 inputs side by side (below)
// BM_Policy_Libtorch (bench_policy_torch.cpp) is libtorch eager on the same weights.
// One inference (or one sweep) per iteration, each timed on its own; single thread.
#include "bench_policy_common.hpp"
#include "nao/quantize.hpp"

#include <Eigen/Core>

#include "nao/policy_kernels.hpp"
#if NAO_POLICY_HAVE_AVX2
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

namespace {

using namespace nao;
using namespace nao::bench;

/// Pushes everything else out of the caches (untimed, before a cold iteration): writes one
/// byte per line of a buffer 4x this machine's 32 MB L3, as 100 ms of other work between two
/// 10 Hz ticks might.
void evictCaches() {
  static std::vector<unsigned char> junk(std::size_t{128} << 20, 1);
  for (std::size_t i = 0; i < junk.size(); i += 64) junk[i] = static_cast<unsigned char>(junk[i] + 1);
  benchmark::ClobberMemory();
}

/// One timed `sweep()` per iteration (manual time; `untimed()` before each, e.g. evicting the
/// caches), then its percentiles.
template <class Untimed, class Sweep>
void timeSweeps(benchmark::State& state, Untimed&& untimed, Sweep&& sweep) {
  Percentiles rec;
  for (auto _ : state) {
    untimed();
    const BenchClock::time_point t0 = BenchClock::now();
    sweep();
    const double sec = secondsSince(t0);
    state.SetIterationTime(sec);
    rec.add(sec);
  }
  rec.report(state);
}

template <class Sweep>
void timeSweeps(benchmark::State& state, Sweep&& sweep) {
  timeSweeps(state, [] {}, sweep);
}

/// stepPolicy with `kernel` (nullptr: benchPolicyKernel's choice), one inference per iteration;
/// `cold`: the caches evicted before each one (untimed).
void runStaticEigen(benchmark::State& state, const PolicyKernel* kernel, WeightPrecision precision = WeightPrecision::kFp32,
                    bool cold = false) {
  const bool int8 = precision == WeightPrecision::kInt8;
  if (!haveModel(state)) return;
  if (kernel != nullptr && !policyKernelSupported(*kernel)) {
    state.SkipWithError((std::string("the ") + policyKernelName(*kernel) + " kernel is not supported here").c_str());
    return;
  }
  const ModelFile& model = paperModel();
  const std::vector<const float*>& p = paperWeights().tensors;  // aligned, as nao_rt --weights
  PolicyWeights<PaperPolicyDims> w = bindPolicyWeights<PaperPolicyDims>(
      p.data(), p.size(), model.header.arch, model.header.conditioning, kernel != nullptr ? *kernel : benchPolicyKernel());
  AlignedBytes blob;
  if (int8) {
    blob = quantizeModelInt8(model);
    bindQuantizedWeights<PaperPolicyDims>(w, blob.data.get());
  } else if (precision == WeightPrecision::kFp32Packed) {
    blob = packModelFp32(model);
    bindPackedWeights<PaperPolicyDims>(w, blob.data.get());
  }
  auto ws = makePolicyWorkspace<PaperPolicyDims>();
  const std::vector<PolicyInput>& inputs = benchInputs();
  Percentiles rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const PolicyInput& in = inputs[i++ % inputs.size()];
    if (cold) evictCaches();
    const BenchClock::time_point t0 = BenchClock::now();
    const auto& a = stepPolicy(w, *ws, in);
    benchmark::DoNotOptimize(a.data());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(s);
  }
  rec.report(state);
  state.SetLabel(policyKernelName(w.kernel));
  if (precision != WeightPrecision::kFp32) {
    // The action difference from fp32 on the same input stream (open loop: both see the same
    // states), rad per step: max and RMS over every joint of every input.
    PolicyWeights<PaperPolicyDims> fp = w;
    unbindQuantizedWeights<PaperPolicyDims>(fp);
    auto ws8 = makePolicyWorkspace<PaperPolicyDims>();
    auto ws32 = makePolicyWorkspace<PaperPolicyDims>();
    double max_d = 0.0, sum_d2 = 0.0, max_a = 0.0;
    for (const PolicyInput& in : inputs) {
      const Eigen::Matrix<float, 5, 1> a8 = stepPolicy(w, *ws8, in);
      const Eigen::Matrix<float, 5, 1> a32 = stepPolicy(fp, *ws32, in);
      for (int j = 0; j < 5; ++j) {
        const double d = static_cast<double>(a8[j]) - static_cast<double>(a32[j]);
        max_d = std::max(max_d, std::fabs(d));
        sum_d2 += d * d;
        max_a = std::max(max_a, std::fabs(static_cast<double>(a32[j])));
      }
    }
    state.counters["max_da_mrad"] = 1e3 * max_d;
    state.counters["rms_da_mrad"] = 1e3 * std::sqrt(sum_d2 / (5.0 * static_cast<double>(inputs.size())));
    state.counters["max_a_mrad"] = 1e3 * max_a;
    if (!int8) state.counters["same_bits"] = max_d == 0.0 ? 1 : 0;  // packed: must be 1
  }
}

// Candidate single-core reads of the weight bytes: sums of 16- or 8-lane loads into 8
// accumulators, `kPasses`×8 loads per loop pass, each line prefetched kPrefetch floats ahead (0:
// none, the hardware prefetcher alone). Which one is fastest depends on the machine, and here it
// depended on the alignment too: before 2026-11-27 the read was of the file's bytes, 16 bytes off
// a line (paperWeights), and the prefetched 8-load pass won (~300 us against ~370-390 us
// unprefetched); from the aligned copy the unprefetched 32-load pass wins (bench/results/
// policy.txt). So BM_WeightStream times every candidate the CPU has and measures the fastest
// (fastestRead) instead of naming one in the source.
typedef float Float4 __attribute__((vector_size(16)));
typedef float Float8 __attribute__((vector_size(32)));
typedef float Float16 __attribute__((vector_size(64)));

/// The read of L-lane vectors V: 8 accumulators, `kPasses`×8 loads a pass, each line prefetched
/// kPrefetch floats ahead (0: none). Inlined into a wrapper compiled for the width's instruction set.
template <class V, int L, int kPasses, std::ptrdiff_t kPrefetch>
__attribute__((always_inline)) inline float streamSumLanes(const float* p, std::ptrdiff_t n) {
  V a[8] = {};
  constexpr std::ptrdiff_t kPass = 8 * L, kStep = kPass * kPasses;
  std::ptrdiff_t i = 0;
  for (; i + kStep <= n; i += kStep)
#pragma GCC unroll 8
    for (int u = 0; u < kPasses; ++u) {
      const float* q = p + i + kPass * u;
      if constexpr (kPrefetch > 0)
#pragma GCC unroll 8
        for (int b = 0; b < kPass; b += 16) __builtin_prefetch(q + kPrefetch + b, 0, 2);  // one per line
#pragma GCC unroll 8
      for (int k = 0; k < 8; ++k) {
        V x;
        std::memcpy(&x, q + L * k, sizeof x);  // an unaligned load
        a[k] += x;
      }
    }
  for (int k = 1; k < 8; ++k) a[0] += a[k];
  float s = 0.0f;
  for (int l = 0; l < L; ++l) s += a[0][l];
  for (; i < n; ++i) s += p[i];
  return s;
}

#if NAO_POLICY_HAVE_AVX2
template <int kPasses, std::ptrdiff_t kPrefetch>
__attribute__((target("avx512f"), noinline)) float streamSumAvx512(const float* p, std::ptrdiff_t n) {
  return streamSumLanes<Float16, 16, kPasses, kPrefetch>(p, n);
}

template <int kPasses, std::ptrdiff_t kPrefetch>
__attribute__((target("avx2"), noinline)) float streamSumAvx2(const float* p, std::ptrdiff_t n) {
  return streamSumLanes<Float8, 8, kPasses, kPrefetch>(p, n);
}
#endif

float streamSumEigen(const float* p, std::ptrdiff_t n) { return Eigen::Map<const Eigen::ArrayXf>(p, n).sum(); }

constexpr std::ptrdiff_t kStreamPrefetchFloats = 16384;  // 64 KB

/// One candidate read: its label, the kernel level its instructions need, the read.
struct StreamRead {
  const char* name;
  PolicyKernel needs;
  float (*sum)(const float*, std::ptrdiff_t);
};

const StreamRead kStreamReads[] = {
#if NAO_POLICY_HAVE_AVX2
    {"avx512-x8-pf64k", PolicyKernel::kAvx512, streamSumAvx512<1, kStreamPrefetchFloats>},
    {"avx512-x32-pf64k", PolicyKernel::kAvx512, streamSumAvx512<4, kStreamPrefetchFloats>},
    {"avx512-x32", PolicyKernel::kAvx512, streamSumAvx512<4, 0>},
    {"avx512-x64", PolicyKernel::kAvx512, streamSumAvx512<8, 0>},
    {"avx2-x8-pf64k", PolicyKernel::kAvx2, streamSumAvx2<1, kStreamPrefetchFloats>},
    {"avx2-x32", PolicyKernel::kAvx2, streamSumAvx2<4, 0>},
#endif
    {"eigen", PolicyKernel::kSse, streamSumEigen},  // last: BM_WeightStream_Eigen's
};
constexpr std::size_t kEigenRead = sizeof(kStreamReads) / sizeof(kStreamReads[0]) - 1;

/// The fastest candidate read of [p, p + n) on this CPU: each one it supports is timed over
/// `sweeps` reads (`untimed()` before each) and the least median wins. Each median goes into a
/// counter `<name>_us`, so the choice can be checked in the output.
template <class Untimed>
const StreamRead& fastestRead(benchmark::State& state, const float* p, std::ptrdiff_t n, int sweeps, Untimed&& untimed) {
  const StreamRead* best = &kStreamReads[kEigenRead];
  double best_us = 0.0;
  for (const StreamRead& r : kStreamReads) {
    if (!policyKernelSupported(r.needs)) continue;
    std::vector<double> us;
    for (int k = 0; k < sweeps; ++k) {
      untimed();
      const BenchClock::time_point t0 = BenchClock::now();
      float s = r.sum(p, n);
      benchmark::DoNotOptimize(s);
      us.push_back(1e6 * secondsSince(t0));
    }
    std::nth_element(us.begin(), us.begin() + sweeps / 2, us.end());
    const double med = us[static_cast<std::size_t>(sweeps / 2)];
    state.counters[std::string(r.name) + "_us"] = med;
    if (best_us == 0.0 || med < best_us) {
      best = &r;
      best_us = med;
    }
  }
  return *best;
}

/// BM_WeightStream: the physical limit, one read of the (aligned) weight bytes by the fastest
/// candidate read this CPU has (fastestRead; the label names it). _Eigen: Eigen's sum (what
/// BM_WeightStream measured before 2026-11-26), reported beside it.
void runWeightStream(benchmark::State& state, bool best, bool cold = false) {
  if (!haveModel(state)) return;
  const float* first = paperWeights().begin();
  const std::ptrdiff_t n = paperWeights().end() - first;
  const auto untimed = [&] {
    if (cold) evictCaches();
  };
  const StreamRead& read = best ? fastestRead(state, first, n, cold ? 15 : 200, untimed) : kStreamReads[kEigenRead];
  timeSweeps(state, untimed, [&] {
    float s = read.sum(first, n);
    benchmark::DoNotOptimize(s);
  });
  state.counters["GB_per_s"] = static_cast<double>(n * 4) / 1e3 / state.counters["p50_us"];
  state.SetLabel(read.name);
}

/// Independent chains a = a + x·y per width: more than latency × pipes of the multiply and of the
/// add, so the issue rate limits, not a chain.
constexpr int kMulAddChains = 12;

/// `iters` rounds of kMulAddChains chains of L lanes (V: a GCC vector of L floats), the multiply
/// and the add separately rounded (as every policy kernel computes: -ffp-contract=off, no FMA),
/// from registers. Inlined into a wrapper compiled for the width's instruction set.
template <class V, int L>
__attribute__((always_inline)) inline float mulAddChains(std::int64_t iters, float seed) {
  V a[kMulAddChains], x[kMulAddChains];
  for (int k = 0; k < kMulAddChains; ++k) {
    a[k] = V{} + seed * static_cast<float>(k);
    x[k] = V{} + (1.0f + seed * static_cast<float>(k));
  }
  // y shrinks by one ulp-sized factor every round, so no product is loop-invariant (a compiler
  // hoists x·y otherwise and times the adds alone); one multiply per round on top of the
  // kMulAddChains multiply-adds. The next round's y is computed first: issued after the round's
  // products (as before 2026-11-26, sixteenth session) its multiply waited behind them, and the
  // next round's products waited on its latency, ~3 cycles a round that no kernel pays
  // (331 us instead of 238 here).
  V y = V{} + 0.999f;
  const V decay = V{} + (1.0f - 0x1p-23f);
  for (std::int64_t i = 0; i < iters; ++i) {
    const V yi = y;
    y = y * decay;
    for (int k = 0; k < kMulAddChains; ++k) a[k] = a[k] + x[k] * yi;
  }
  for (int k = 1; k < kMulAddChains; ++k) a[0] = a[0] + a[k];
  float s = 0.0f;
  for (int i = 0; i < L; ++i) s += a[0][i];
  return s;
}

__attribute__((noinline)) float mulAddSse(std::int64_t iters, float seed) { return mulAddChains<Float4, 4>(iters, seed); }
#if NAO_POLICY_HAVE_AVX2
__attribute__((target("avx2"), noinline)) float mulAddAvx2(std::int64_t iters, float seed) {
  return mulAddChains<Float8, 8>(iters, seed);
}
__attribute__((target("avx512f"), noinline)) float mulAddAvx512(std::int64_t iters, float seed) {
  return mulAddChains<Float16, 16>(iters, seed);
}
#endif

/// BM_MulAddFloor: the arithmetic limit of the fp32 step, beside BM_WeightStream's read limit.
/// A step multiplies every weight of the model's matrices by each of the tick's J = 5 tokens
/// and adds the product (a weight is read once and used J times); this issues that many
/// separately rounded multiply-adds at the CPU's widest kernel width with nothing to load.
/// A step takes at least the larger of this and the read.
void runMulAddFloor(benchmark::State& state) {
  if (!haveModel(state)) return;
  const ModelFile& model = paperModel();
  std::int64_t weights = 0;
  for (const auto& t : model.tensors) {
    const std::string& n = t.spec.name;
    const bool matrix = t.spec.shape.size() == 2 && n.find("age_bias") == std::string::npos &&
                        n.rfind("embed.", 0) != 0;  // embeddings are looked up, not multiplied
    if (matrix) weights += static_cast<std::int64_t>(t.spec.count());
  }
  const std::int64_t mul_adds = weights * 5;
  int lanes = 4;
#if NAO_POLICY_HAVE_AVX2
  if (policyKernelSupported(PolicyKernel::kAvx512))
    lanes = 16;
  else if (policyKernelSupported(PolicyKernel::kAvx2))
    lanes = 8;
#endif
  const std::int64_t iters = mul_adds / (static_cast<std::int64_t>(lanes) * kMulAddChains);
  Percentiles rec;
  float seed = 1e-7f;
  for (auto _ : state) {
    const BenchClock::time_point t0 = BenchClock::now();
    float s = 0.0f;
#if NAO_POLICY_HAVE_AVX2
    if (lanes == 16) s = mulAddAvx512(iters, seed);
    if (lanes == 8) s = mulAddAvx2(iters, seed);
#endif
    if (lanes == 4) s = mulAddSse(iters, seed);
    benchmark::DoNotOptimize(s);
    const double sec = secondsSince(t0);
    state.SetIterationTime(sec);
    rec.add(sec);
    seed += 1e-9f;
  }
  rec.report(state);
  state.counters["mul_adds_M"] = static_cast<double>(mul_adds) / 1e6;
  state.counters["G_mul_add_per_s"] = static_cast<double>(mul_adds) / 1e3 / state.counters["p50_us"];
  state.SetLabel(lanes == 16 ? "avx512" : lanes == 8 ? "avx2" : "sse");
}

#if NAO_POLICY_HAVE_AVX2
// BM_Layout_Strided / BM_Layout_Packed: where the fp32 step's products lose to the read
// (2026-11-26). 24 distinct 512x512 matrices (24 MB, the model's size; the FFN's middle
// matrices are this shape) times J = 5 tokens with AVX-512, one sweep per iteration:
//   _Strided: the runtime's kernel (affineTokensAvx512) on the column-major matrices of
//             model.bin: a block of 32 rows reads 128 bytes of each of a strip's 16 columns,
//             2 KB apart;
//   _Packed:  the runtime's packed kernel (affineTokensPackedAvx512) on the same matrices packed
//             by packMatrixFp32: each (strip, block) 2 KB in a row, read in address order.
// Both add each row's terms in k order, multiply then add: the same bits (counter same_bits).
constexpr int kLayoutRows = 512, kLayoutCols = 512, kLayoutTokens = 5, kLayoutMatrices = 24;

void runLayout(benchmark::State& state, bool packed) {
  if (!policyKernelSupported(PolicyKernel::kAvx512)) {
    state.SkipWithError("the AVX-512 kernel is not supported here");
    return;
  }
  constexpr std::size_t kSize = static_cast<std::size_t>(kLayoutRows) * kLayoutCols;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.1f, 0.1f);
  // Each layout's matrices back to back in one 64-byte aligned block, as in the runtime's blobs
  // (before 2026-11-27 they were separate vectors, 16 bytes off a line and not contiguous).
  const auto w_all = alignedFloats(kSize * kLayoutMatrices), p_all = alignedFloats(kSize * kLayoutMatrices);
  std::vector<float*> W(kLayoutMatrices), P(kLayoutMatrices);
  for (int m = 0; m < kLayoutMatrices; ++m) {
    W[m] = w_all.get() + kSize * static_cast<std::size_t>(m);
    P[m] = p_all.get() + kSize * static_cast<std::size_t>(m);
    for (std::size_t i = 0; i < kSize; ++i) W[m][i] = u(rng);
    packMatrixFp32(W[m], kLayoutRows, kLayoutCols, P[m]);
  }
  std::vector<float> X(static_cast<std::size_t>(kLayoutCols) * kLayoutTokens), Y(kLayoutRows * kLayoutTokens),
      Z(kLayoutRows * kLayoutTokens);
  for (float& x : X) x = u(rng);
  detail::affineTokensAvx512<kLayoutRows, kLayoutCols, kLayoutTokens, false>(W[0], nullptr, X.data(), Y.data());
  detail::affineTokensPackedAvx512<kLayoutRows, kLayoutCols, kLayoutTokens, false>(P[0], nullptr, X.data(),
                                                                                   Z.data());
  const bool same = std::memcmp(Y.data(), Z.data(), Y.size() * sizeof(float)) == 0;
  timeSweeps(state, [&] {
    for (int m = 0; m < kLayoutMatrices; ++m) {
      if (packed)
        detail::affineTokensPackedAvx512<kLayoutRows, kLayoutCols, kLayoutTokens, false>(P[m], nullptr,
                                                                                         X.data(), Y.data());
      else
        detail::affineTokensAvx512<kLayoutRows, kLayoutCols, kLayoutTokens, false>(W[m], nullptr, X.data(),
                                                                                   Y.data());
      benchmark::DoNotOptimize(Y.data());
    }
  });
  state.counters["same_bits"] = same ? 1.0 : 0.0;
  state.counters["GB_per_s"] = static_cast<double>(kLayoutMatrices * kSize * 4) / 1e3 / state.counters["p50_us"];
  state.counters["G_mul_add_per_s"] =
      static_cast<double>(kLayoutMatrices) * kSize * kLayoutTokens / 1e3 / state.counters["p50_us"];
}
#endif

#if NAO_POLICY_HAVE_AVX2
// BM_Int8Layout_Pairs / BM_Int8Layout_Quads: what the int8 blob's layout costs the 7-bit
// products (2026-11-26). 16 distinct 512x512 int8 matrices (4 MB: the FFN's w1 and w2 of the
// paper model's 8 layers) times J = 5 non-negative tokens (the 7-bit range), one sweep per
// iteration:
//   _Pairs: the runtime's kernel (accumulateInt8QuadsAvx512) on quantizeMatrixInt8's blob, whose
//           pairs of inputs are interleaved: 2 vpermt2w per 10 vpdpbusd make each lane one row's
//           4 inputs;
//   _Quads: a candidate kernel (here only) on the same bytes with 4 inputs of a row side by side,
//           each (strip of 8 quads, block of 32 rows) 1 KB in a row as the kernel reads it:
//           vpdpbusd straight from the load, in address order.
// Both make exact int32 sums: the same accumulators (counter same_sums).
constexpr int kInt8LayoutRows = 512, kInt8LayoutCols = 512, kInt8LayoutTokens = 5, kInt8LayoutMatrices = 16;
using Int8LayoutTokens = detail::QuantTokens<kInt8LayoutCols, kInt8LayoutTokens>;

/// The candidate: strips of 8 quads; in each, blocks of 32 rows (two zmm loads per quad, the
/// block's 1 KB in a row), 2·J accumulators, the block's share of the next strip prefetched.
__attribute__((target("avx512f,avx512bw,avx512vnni,avx2"), noinline)) void int8QuadLayoutAvx512(
    const std::int8_t* Wq4, const Int8LayoutTokens& x, std::int32_t* acc) {
  constexpr int Out = kInt8LayoutRows, Q = kInt8LayoutCols / 4, J = kInt8LayoutTokens, kStrip = 8;
  for (int q0 = 0; q0 < Q; q0 += kStrip) {
    const bool more = q0 + kStrip < Q;
    for (int r = 0; r < Out; r += 32) {
      const std::int8_t* share = more ? Wq4 + (static_cast<std::ptrdiff_t>(q0 + kStrip) * Out + r * kStrip) * 4 : nullptr;
      // Block-contiguous: (strip, block of 32 rows) is kStrip·128 bytes in a row.
      const std::int8_t* blk = Wq4 + (static_cast<std::ptrdiff_t>(q0) * Out + r * kStrip) * 4;
      __m512i a[2][J];
      for (int t = 0; t < J; ++t) a[0][t] = a[1][t] = _mm512_setzero_si512();
#pragma GCC unroll 2
      for (int k = 0; k < kStrip; ++k) {
        if (more) {
          __builtin_prefetch(share + 128 * k, 0, 2);
          __builtin_prefetch(share + 128 * k + 64, 0, 2);
        }
        const std::int8_t* w = blk + 128 * k;
        const __m512i v0 = _mm512_loadu_si512(w), v1 = _mm512_loadu_si512(w + 64);
#pragma GCC unroll 8
        for (int t = 0; t < J; ++t) {
          const __m512i xq = _mm512_set1_epi32(x.quads[t * Q + q0 + k]);
          a[0][t] = _mm512_dpbusd_epi32(a[0][t], xq, v0);
          a[1][t] = _mm512_dpbusd_epi32(a[1][t], xq, v1);
        }
      }
      for (int t = 0; t < J; ++t)
        for (int i = 0; i < 2; ++i) {
          std::int32_t* y = acc + t * Out + r + 16 * i;
          _mm512_storeu_si512(y, q0 == 0 ? a[i][t] : _mm512_add_epi32(_mm512_loadu_si512(y), a[i][t]));
        }
    }
  }
}

void runInt8Layout(benchmark::State& state, bool quads) {
  if (!policyKernelSupported(PolicyKernel::kAvx512)) {
    state.SkipWithError("the AVX-512 kernel is not supported here");
    return;
  }
  constexpr int Out = kInt8LayoutRows, In = kInt8LayoutCols, J = kInt8LayoutTokens;
  const std::size_t section = detail::quantSectionBytes(Out, In);
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(-0.1f, 0.1f), pos(0.0f, 1.0f);
  std::vector<std::vector<std::uint8_t>> blob(kInt8LayoutMatrices), quad(kInt8LayoutMatrices);
  // The first 64-byte boundary of a buffer allocated 64 bytes long.
  const auto aligned = [](std::vector<std::uint8_t>& v) {
    return v.data() + (64 - reinterpret_cast<std::uintptr_t>(v.data()) % 64) % 64;
  };
  std::vector<float> w(static_cast<std::size_t>(Out) * In);
  for (int m = 0; m < kInt8LayoutMatrices; ++m) {
    for (float& v : w) v = u(rng);
    blob[m].assign(section + 64, 0);
    std::uint8_t* sec = aligned(blob[m]);
    quantizeMatrixInt8(w.data(), Out, In, sec);
    quad[m].assign(static_cast<std::size_t>(Out) * In + 64, 0);
    std::uint8_t* q4 = aligned(quad[m]);
    // pairs: byte (p·Out + r)·2 + e; quads: strip s of 8 quads, block b of 32 rows, quad c of
    // the strip, row i of the block: ((s·Out/32 + b)·8 + c)·128 + i·4 + e.
    for (int k = 0; k < In; ++k)
      for (int r = 0; r < Out; ++r) {
        const std::size_t qd = static_cast<std::size_t>(k / 4), st = qd / 8, c = qd % 8;
        const std::size_t b = static_cast<std::size_t>(r / 32), i = static_cast<std::size_t>(r % 32);
        q4[((st * (Out / 32) + b) * 8 + c) * 128 + i * 4 + k % 4] =
            sec[(static_cast<std::size_t>(k / 2) * Out + r) * 2 + k % 2];
      }
  }
  const auto weights = [&](std::vector<std::uint8_t>& v) { return reinterpret_cast<const std::int8_t*>(aligned(v)); };
  std::vector<float> X(static_cast<std::size_t>(In) * J);
  for (float& v : X) v = pos(rng);
  Int8LayoutTokens x;
  detail::quantizeTokensInt8Avx512<In, J>(X.data(), x);
  std::vector<std::int32_t> acc(static_cast<std::size_t>(Out) * J), ref(acc.size());
  detail::accumulateInt8QuadsAvx512<Out, In, J>(weights(blob[0]), x, ref.data());
  int8QuadLayoutAvx512(weights(quad[0]), x, acc.data());
  const bool same = x.positive && acc == ref;
  timeSweeps(state, [&] {
    for (int m = 0; m < kInt8LayoutMatrices; ++m) {
      if (quads)
        int8QuadLayoutAvx512(weights(quad[m]), x, acc.data());
      else
        detail::accumulateInt8QuadsAvx512<Out, In, J>(weights(blob[m]), x, acc.data());
      benchmark::DoNotOptimize(acc.data());
    }
  });
  state.counters["same_sums"] = same ? 1.0 : 0.0;
  state.counters["GB_per_s"] = static_cast<double>(kInt8LayoutMatrices) * Out * In / 1e3 / state.counters["p50_us"];
}
#endif

/// One row per registered benchmark: kernel forced (none: the runtime's choice), precision,
/// caches evicted before every iteration (cold: 200 iterations, each eviction writes 128 MB).
struct PolicyCase {
  const char* name;
  bool forced;
  PolicyKernel kernel;
  WeightPrecision precision;
  bool cold;
};

constexpr PolicyCase kPolicyCases[] = {
    {"BM_Policy_StaticEigen", false, PolicyKernel::kSse, WeightPrecision::kFp32, false},
    {"BM_Policy_StaticEigen_SSE", true, PolicyKernel::kSse, WeightPrecision::kFp32, false},
    {"BM_Policy_StaticEigen_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kFp32, false},
    {"BM_Policy_StaticEigen_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kFp32, false},
    {"BM_Policy_Packed", false, PolicyKernel::kSse, WeightPrecision::kFp32Packed, false},
    {"BM_Policy_Packed_SSE", true, PolicyKernel::kSse, WeightPrecision::kFp32Packed, false},
    {"BM_Policy_Packed_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kFp32Packed, false},
    {"BM_Policy_Packed_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kFp32Packed, false},
    {"BM_Policy_Int8", false, PolicyKernel::kSse, WeightPrecision::kInt8, false},
    {"BM_Policy_Int8_SSE", true, PolicyKernel::kSse, WeightPrecision::kInt8, false},
    {"BM_Policy_Int8_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kInt8, false},
    {"BM_Policy_Int8_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kInt8, false},
    // Cold: every step after the caches were evicted (the 10 Hz loop's case when other work
    // runs between ticks).
    {"BM_Policy_Cold_SSE", true, PolicyKernel::kSse, WeightPrecision::kFp32, true},
    {"BM_Policy_Cold_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kFp32, true},
    {"BM_Policy_Cold_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kFp32, true},
    {"BM_Policy_Packed_Cold_SSE", true, PolicyKernel::kSse, WeightPrecision::kFp32Packed, true},
    {"BM_Policy_Packed_Cold_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kFp32Packed, true},
    {"BM_Policy_Packed_Cold_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kFp32Packed, true},
    {"BM_Policy_Int8_Cold_AVX2", true, PolicyKernel::kAvx2, WeightPrecision::kInt8, true},
    {"BM_Policy_Int8_Cold_AVX512", true, PolicyKernel::kAvx512, WeightPrecision::kInt8, true},
};

/// The weight reads: the fastest (BM_WeightStream), Eigen's, and the fastest after eviction.
struct StreamCase {
  const char* name;
  bool best;
  bool cold;
};

constexpr StreamCase kStreamCases[] = {
    {"BM_WeightStream", true, false}, {"BM_WeightStream_Eigen", false, false}, {"BM_WeightStream_Cold", true, true}};

benchmark::internal::Benchmark* timed(benchmark::internal::Benchmark* b, bool cold) {
  return b->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(cold ? 200 : 2000);
}

// Registered in this order: the hot policy steps, the hot reads, then the cold ones.
const bool kRegistered = [] {
  for (bool cold : {false, true}) {
    for (const PolicyCase& c : kPolicyCases)
      if (c.cold == cold)
        timed(benchmark::RegisterBenchmark(c.name,
                                           [c](benchmark::State& state) {
                                             runStaticEigen(state, c.forced ? &c.kernel : nullptr, c.precision, c.cold);
                                           }),
              cold);
    for (const StreamCase& c : kStreamCases)
      if (c.cold == cold)
        timed(benchmark::RegisterBenchmark(c.name, [c](benchmark::State& state) { runWeightStream(state, c.best, c.cold); }),
              cold);
    if (!cold) timed(benchmark::RegisterBenchmark("BM_MulAddFloor", runMulAddFloor), false);
#if NAO_POLICY_HAVE_AVX2
    if (!cold) {
      timed(benchmark::RegisterBenchmark("BM_Layout_Strided", [](benchmark::State& st) { runLayout(st, false); }), true);
      timed(benchmark::RegisterBenchmark("BM_Layout_Packed", [](benchmark::State& st) { runLayout(st, true); }), true);
      timed(benchmark::RegisterBenchmark("BM_Int8Layout_Pairs", [](benchmark::State& st) { runInt8Layout(st, false); }),
            true);
      timed(benchmark::RegisterBenchmark("BM_Int8Layout_Quads", [](benchmark::State& st) { runInt8Layout(st, true); }),
            true);
    }
#endif
  }
  return true;
}();

}  // namespace
