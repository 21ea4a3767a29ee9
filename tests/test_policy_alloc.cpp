// Real-time property: policy inference (stepPolicy) allocates nothing.
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "support/alloc_counter.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

using namespace nao;
using nao::test::CountAllocations;

namespace {

float uniform(std::mt19937_64& rng, double lo, double hi) {
  return static_cast<float>(lo + (hi - lo) * (static_cast<double>(rng() >> 11) * 0x1.0p-53));
}

// Runs n_steps policy steps over inputs prepared beforehand, as rollouts of 97 ticks (the
// stream is reset between them, the rings wrap inside them; movement and step indices include
// out-of-range values, the last input of every rollout is NaN) and returns the allocations counted.
template <class Dims>
std::int64_t allocationsOverSteps(Conditioning c, int n_steps, double& sink, bool int8 = false,
                                  const PolicyArch& arch = Dims::arch()) {
  const std::vector<TensorSpec> manifest = policyManifest(arch);
  std::mt19937_64 rng(7);
  std::vector<std::vector<float>> tensors;
  for (const TensorSpec& s : manifest) {
    std::vector<float> v(s.count());
    const bool is_std = s.name.size() > 4 && s.name.compare(s.name.size() - 4, 4, "_std") == 0;
    for (float& x : v) x = is_std ? uniform(rng, 0.05, 0.5) : uniform(rng, -0.1, 0.1);
    tensors.push_back(std::move(v));
  }
  std::vector<const float*> ptrs;
  for (const std::vector<float>& t : tensors) ptrs.push_back(t.data());
  PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c);
  AlignedBytes blob;  // int8: the matrices through the int8 kernels (stack scratch only)
  if (int8) {
    blob = quantizePolicyInt8(w);
    bindQuantizedWeights<Dims>(w, blob.data.get());
  }
  const auto ws = makePolicyWorkspace<Dims>();

  std::vector<PolicyInput> inputs(static_cast<std::size_t>(n_steps));
  for (int i = 0; i < n_steps; ++i) {
    PolicyInput& in = inputs[static_cast<std::size_t>(i)];
    for (int j = 0; j < 5; ++j) {
      in.q[j] = uniform(rng, -1.5, 1.5);
      in.a_prev[j] = uniform(rng, -0.1, 0.1);
      in.r[j] = uniform(rng, -1.5, 1.5);
    }
    if (i % 97 == 96) in.q[1] = std::nanf("");
    in.movement = i % (arch.movements + 2) - 1;
    in.step = i % (arch.max_steps + 20) - 5;
  }

  CountAllocations counter;
  int i = 0;
  for (const PolicyInput& in : inputs) {
    if (i++ % 97 == 0) resetPolicyStream(*ws);
    if (i % 2 == 0) {
      const Eigen::Matrix<float, 5, 1>& a = stepPolicy(w, *ws, in);
      if (a.allFinite()) sink += static_cast<double>(a[0]) + static_cast<double>(ws->score[4]);
    } else {
      // The step's parts, with the attention ablation's probe (a body part masked) and the
      // ensemble's read-only view in between: real-time code too.
      encodePolicyTick(w, *ws, in);
      decodePolicyTick(w, *ws, 1u << (i % 5));
      decodePolicyTick(w, *ws);
      const Eigen::Matrix<float, 5, 1> e = ensembledAction(w, *ws);
      const Eigen::Matrix<float, 5, 1>& a = commitPolicyTick(w, *ws, in);
      if (a.allFinite() && e.allFinite()) sink += static_cast<double>(a[0]) + static_cast<double>(e[1]);
    }
    sink += static_cast<double>(snapToCentroid(w, in.movement, in.q));
  }
  return counter.count();
}

}  // namespace

TEST_CASE("the allocation counter sees an allocation (the checks below can fail)") {
  CountAllocations counter;
  std::vector<float>* v = new std::vector<float>(1000, 1.0f);
  const std::int64_t n_alloc = counter.count();
  delete v;
  CHECK(n_alloc >= 2);
}

TEST_CASE("10,000 policy steps with the paper dimensions allocate nothing") {
  constexpr int kSteps = 10000;
  double sink = 0.0;
  const std::int64_t n_alloc = allocationsOverSteps<PaperPolicyDims>(Conditioning::kReference, kSteps, sink);
  CHECK_MESSAGE(n_alloc == 0, "expected no heap allocation in ", kSteps, " steps, got ", n_alloc);
  CHECK(std::isfinite(sink));
}

TEST_CASE("10,000 policy steps with int8 weights allocate nothing, paper and small dimensions") {
  constexpr int kSteps = 10000;
  double sink = 0.0;
  std::int64_t n_alloc = allocationsOverSteps<PaperPolicyDims>(Conditioning::kReference, kSteps, sink, true);
  CHECK_MESSAGE(n_alloc == 0, "paper, int8: expected no heap allocation in ", kSteps, " steps, got ", n_alloc);
  n_alloc = allocationsOverSteps<SmallPolicyDims>(Conditioning::kAutonomous, kSteps, sink, true);
  CHECK_MESSAGE(n_alloc == 0, "small, int8: expected no heap allocation in ", kSteps, " steps, got ", n_alloc);
  CHECK(std::isfinite(sink));
}

TEST_CASE("10,000 policy steps with the small dimensions allocate nothing, both conditioning modes") {
  constexpr int kSteps = 10000;
  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    double sink = 0.0;
    const std::int64_t n_alloc = allocationsOverSteps<SmallPolicyDims>(c, kSteps, sink);
    CHECK_MESSAGE(n_alloc == 0, conditioningName(c), ": expected no heap allocation in ", kSteps, " steps, got ",
                  n_alloc);
    CHECK(std::isfinite(sink));
  }
}

TEST_CASE("10,000 policy steps with a chunk of 5 allocate nothing, both conditioning modes") {
  constexpr int kSteps = 10000;
  PolicyArch arch = SmallPolicyDims::arch();
  arch.chunk = 5;
  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    double sink = 0.0;
    const std::int64_t n_alloc = allocationsOverSteps<SmallPolicyDims>(c, kSteps, sink, false, arch);
    CHECK_MESSAGE(n_alloc == 0, conditioningName(c), ": expected no heap allocation in ", kSteps, " steps, got ",
                  n_alloc);
    CHECK(std::isfinite(sink));
  }
}
