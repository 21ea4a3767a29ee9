// Shared setup of the policy benchmarks: the committed paper model (models/default.bin) and a
// fixed set of inputs, prepared once before any timing.
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "rt_run.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <random>
#include <string>
#include <vector>

namespace nao::bench {

/// The kernel the benchmarks bind the weights with when they do not force one: environment
/// variable NAO_POLICY_KERNEL, the benchmarks' own switch (the runtime reads no environment: the
/// kernel is the bound weights', passed at bind). Unset, "", "auto", "avx512" or anything else:
/// the best this CPU runs; "sse": kSse; "avx2": kAvx2 if supported, else kSse.
inline PolicyKernel benchPolicyKernel() {
  const char* env = std::getenv("NAO_POLICY_KERNEL");
  if (env != nullptr && std::strcmp(env, "sse") == 0) return PolicyKernel::kSse;
  if (env != nullptr && std::strcmp(env, "avx2") == 0)
    return policyKernelSupported(PolicyKernel::kAvx2) ? PolicyKernel::kAvx2 : PolicyKernel::kSse;
  return bestPolicyKernel();
}

/// False (and the benchmark marked skipped with the reason) when models/default.bin is absent.
inline bool haveModel(benchmark::State& state) {
  std::FILE* f = std::fopen(NAO_BENCH_MODEL, "rb");
  if (f == nullptr) {
    state.SkipWithError("no " NAO_BENCH_MODEL " (train it: toolchain/nao train)");
    return false;
  }
  std::fclose(f);
  return true;
}

inline const ModelFile& paperModel() {
  static const ModelFile model = readModelFile(NAO_BENCH_MODEL);
  return model;
}

/// The paper model's tensors as nao_rt --weights holds them (rt_run.hpp, copyWeightFile: 64-byte
/// aligned, each padded to 16 floats). The file's bytes are a std::vector, which malloc places 16
/// bytes off a cache line here, so model.data(i) is too: every 64-byte load from it spans two
/// lines, and the fastest read of it measured ~1.3x slower than of the aligned copy
/// (bench/results/policy.txt, 2026-11-27). Benchmarks read the weights from here.
struct AlignedWeights {
  rt::WeightStorage storage;
  std::vector<const float*> tensors;  ///< manifest order, each 64-byte aligned
  const float* begin() const { return storage.floats.get(); }
  const float* end() const { return tensors.back() + paperModel().tensors.back().spec.count(); }
};

/// `n` zero floats, 64-byte aligned.
inline std::unique_ptr<float[], rt::WeightStorage::Free> alignedFloats(std::size_t n) {
  std::unique_ptr<float[], rt::WeightStorage::Free> f(
      static_cast<float*>(::operator new[](n * sizeof(float), std::align_val_t{kModelAlignment})));
  std::fill(f.get(), f.get() + n, 0.0f);
  return f;
}

inline const AlignedWeights& paperWeights() {
  static const AlignedWeights w = [] {
    AlignedWeights a;
    a.tensors = rt::copyWeightFile(paperModel(), a.storage);
    return a;
  }();
  return w;
}

/// Bytes of weight data one inference streams: every manifest tensor's floats.
inline std::size_t weightBytes() {
  std::size_t n = 0;
  for (const TensorEntry& t : paperModel().tensors) n += t.spec.count() * sizeof(float);
  return n;
}

/// 256 inputs inside the arm's range (q and r uniform in wide bounds, small a(t-1)).
inline const std::vector<PolicyInput>& benchInputs() {
  static const std::vector<PolicyInput> inputs = [] {
    std::mt19937_64 rng(20261122);
    auto u = [&rng](double lo, double hi) {
      return static_cast<float>(lo + (hi - lo) * static_cast<double>(rng() >> 11) * 0x1.0p-53);
    };
    std::vector<PolicyInput> v(256);
    for (std::size_t n = 0; n < v.size(); ++n) {
      for (int j = 0; j < 5; ++j) {
        v[n].q[j] = u(-1.5, 1.5);
        v[n].a_prev[j] = u(-0.05, 0.05);
        v[n].r[j] = u(-1.5, 1.5);
      }
      v[n].movement = static_cast<int>(n % 3);
      v[n].step = static_cast<int>(n % 200);
    }
    return v;
  }();
  return inputs;
}

/// Per-iteration times (manual timing) -> p50/p99 counters in µs.
struct Percentiles {
  std::vector<double> us;
  void add(double seconds) { us.push_back(seconds * 1e6); }
  void report(benchmark::State& state) {
    if (us.empty()) return;
    std::sort(us.begin(), us.end());
    const auto at = [&](double f) {
      return us[std::min(us.size() - 1, static_cast<std::size_t>(f * static_cast<double>(us.size())))];
    };
    state.counters["p50_us"] = at(0.50);
    state.counters["p99_us"] = at(0.99);
    state.counters["weight_MB"] = static_cast<double>(weightBytes()) / 1e6;
  }
};

using BenchClock = std::chrono::steady_clock;

inline double secondsSince(BenchClock::time_point t0) {
  return std::chrono::duration<double>(BenchClock::now() - t0).count();
}

}  // namespace nao::bench
