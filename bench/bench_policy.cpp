// Policy inference latency on the paper configuration (the committed models/default.bin):
//   BM_Policy_StaticEigen  the runtime's fixed-size float stepPolicy (nao/policy.hpp) with the
//                          kernel the runtime picks (NAO_POLICY_KERNEL, CPU; the label names it)
//   BM_Policy_StaticEigen_SSE / _AVX2  the same with the kernel forced (nao/policy_kernels.hpp);
//                          _AVX2 is skipped with a message on a CPU without AVX2
//   BM_Policy_Int8 / _SSE / _AVX2  the same with the attention and FFN matrices in int8
//                          (nao/quantize.hpp: quantised from the fp32 model at set-up, the bytes
//                          nao_codegen --precision int8 compiles in)
//   BM_WeightStream        the physical limit: one read of the same weight bytes (a vectorised
//                          sum over the model's tensor data), i.e. weight bytes / single-core
//                          read bandwidth, measured in the same run
// BM_Policy_Libtorch (bench_policy_torch.cpp) is libtorch eager on the same weights.
// One inference (or one sweep) per iteration, each timed on its own; single thread.
#include "bench_policy_common.hpp"
#include "nao/quantize.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <string>

namespace {

using namespace nao;
using namespace nao::bench;

/// stepPolicy with `kernel` (nullptr: the runtime's choice), one inference per iteration.
void runStaticEigen(benchmark::State& state, const PolicyKernel* kernel, bool int8 = false) {
  if (!haveModel(state)) return;
  const PolicyKernel saved = activePolicyKernel();
  if (kernel != nullptr && !selectPolicyKernel(*kernel)) {
    state.SkipWithError((std::string("the ") + policyKernelName(*kernel) + " kernel is not supported here").c_str());
    return;
  }
  const ModelFile& model = paperModel();
  std::vector<const float*> p;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) p.push_back(model.data(i));
  PolicyWeights<PaperPolicyDims> w = bindPolicyWeights<PaperPolicyDims>(p.data(), p.size(), model.header.conditioning);
  AlignedBytes blob;
  if (int8) {
    blob = quantizeModelInt8(model);
    bindQuantizedWeights<PaperPolicyDims>(w, blob.data.get());
  }
  auto ws = makePolicyWorkspace<PaperPolicyDims>();
  const std::vector<PolicyInput>& inputs = benchInputs();
  Percentiles rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const PolicyInput& in = inputs[i++ % inputs.size()];
    const BenchClock::time_point t0 = BenchClock::now();
    const auto& a = stepPolicy(w, *ws, in);
    benchmark::DoNotOptimize(a.data());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(s);
  }
  rec.report(state);
  state.SetLabel(policyKernelName(activePolicyKernel()));
  if (int8) {
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
  }
  selectPolicyKernel(saved);
}

void BM_Policy_StaticEigen(benchmark::State& state) { runStaticEigen(state, nullptr); }

void BM_Policy_StaticEigen_SSE(benchmark::State& state) {
  const PolicyKernel k = PolicyKernel::kSse;
  runStaticEigen(state, &k);
}

void BM_Policy_StaticEigen_AVX2(benchmark::State& state) {
  const PolicyKernel k = PolicyKernel::kAvx2;
  runStaticEigen(state, &k);
}

void BM_Policy_Int8(benchmark::State& state) { runStaticEigen(state, nullptr, true); }

void BM_Policy_Int8_SSE(benchmark::State& state) {
  const PolicyKernel k = PolicyKernel::kSse;
  runStaticEigen(state, &k, true);
}

void BM_Policy_Int8_AVX2(benchmark::State& state) {
  const PolicyKernel k = PolicyKernel::kAvx2;
  runStaticEigen(state, &k, true);
}

void BM_WeightStream(benchmark::State& state) {
  if (!haveModel(state)) return;
  const ModelFile& model = paperModel();
  // The tensor data is one contiguous region (64-byte aligned tensors back to back).
  const float* first = model.data(0);
  const float* last = model.data(model.tensors.size() - 1) + model.tensors.back().spec.count();
  const Eigen::Map<const Eigen::ArrayXf> all(first, last - first);
  Percentiles rec;
  for (auto _ : state) {
    const BenchClock::time_point t0 = BenchClock::now();
    float s = all.sum();
    benchmark::DoNotOptimize(s);
    const double sec = secondsSince(t0);
    state.SetIterationTime(sec);
    rec.add(sec);
  }
  rec.report(state);
  state.counters["GB_per_s"] = static_cast<double>((last - first) * 4) / 1e3 / state.counters["p50_us"];
}

}  // namespace

BENCHMARK(BM_Policy_StaticEigen)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_Policy_StaticEigen_SSE)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_Policy_StaticEigen_AVX2)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_Policy_Int8)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_Policy_Int8_SSE)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_Policy_Int8_AVX2)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
BENCHMARK(BM_WeightStream)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(2000);
