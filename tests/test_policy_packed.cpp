// Packed fp32 weights (policy_kernels.hpp "Packed fp32", nao/quantize.hpp packModelFp32):
// - packMatrixFp32 puts W(32b + i, 16s + c) at ((s·out/32 + b)·16 + c)·32 + i, and refuses
//   shapes the layout does not take;
// - affineTokensPacked over the packed copy equals affineTokens over W bit for bit with every
//   kernel the CPU has, on the model's shapes and a head's slice of Wo; a wrongly packed copy
//   differs (the comparison can fail);
// - stepPolicy with bound packed views: the same actions and attention record as fp32, bit for
//   bit, with every kernel, over rollouts longer than the window; the blob from the file and from
//   the views are the same bytes; int8 binding drops the packed views; warmPolicy reads each
//   matrix once (the packed copy instead of the view, not both).
#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <random>
#include <stdexcept>
#include <vector>

using namespace nao;

namespace {

/// The kernels this CPU and build can run.
std::vector<PolicyKernel> supportedKernels() {
  std::vector<PolicyKernel> k;
  for (PolicyKernel c : {PolicyKernel::kSse, PolicyKernel::kAvx2, PolicyKernel::kAvx512})
    if (policyKernelSupported(c)) k.push_back(c);
  return k;
}

std::vector<float> randomVector(std::mt19937_64& rng, std::size_t n, double lo, double hi) {
  std::vector<float> v(n);
  for (float& x : v) x = test::uniformFloat(rng, lo, hi);
  return v;
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

template <int Out, int In, int J>
void checkPackedShape(std::uint64_t seed) {
  CAPTURE(Out);
  CAPTURE(In);
  std::mt19937_64 rng(seed);
  const std::vector<float> W = randomVector(rng, static_cast<std::size_t>(Out) * In, -0.3, 0.3);
  const std::vector<float> b = randomVector(rng, Out, -0.5, 0.5);
  const std::vector<float> X = randomVector(rng, static_cast<std::size_t>(In) * J, -2.0, 2.0);
  std::vector<float> P(W.size());
  packMatrixFp32(W.data(), Out, In, P.data());
  for (PolicyKernel k : supportedKernels()) {
    CAPTURE(policyKernelName(k));
    std::vector<float> want(static_cast<std::size_t>(Out) * J), got(want.size(), NAN);
    detail::affineTokens<Out, In, J, true>(k, W.data(), b.data(), X.data(), want.data());
    detail::affineTokensPacked<Out, In, J, true>(k, P.data(), b.data(), X.data(), got.data());
    CHECK(sameBits(got, want));
    // No bias, no ReLU.
    detail::affineTokens<Out, In, J, false>(k, W.data(), nullptr, X.data(), want.data());
    std::fill(got.begin(), got.end(), NAN);
    detail::affineTokensPacked<Out, In, J, false>(k, P.data(), nullptr, X.data(), got.data());
    CHECK(sameBits(got, want));
    // Copied wrong: two columns of the first block swapped. The comparison can fail.
    std::vector<float> bad = P;
    for (int i = 0; i < detail::kPackBlock; ++i) std::swap(bad[static_cast<std::size_t>(i)], bad[static_cast<std::size_t>(detail::kPackBlock + i)]);
    detail::affineTokensPacked<Out, In, J, false>(k, bad.data(), nullptr, X.data(), got.data());
    CHECK_FALSE(sameBits(got, want));
  }
}

}  // namespace

TEST_CASE("packMatrixFp32: W(32b + i, 16s + c) at ((s·out/32 + b)·16 + c)·32 + i; other shapes refused") {
  constexpr int out = 64, in = 48;
  std::vector<float> W(static_cast<std::size_t>(out) * in);
  for (std::size_t i = 0; i < W.size(); ++i) W[i] = static_cast<float>(i);  // W(r, k) = k·out + r
  std::vector<float> P(W.size(), -1.0f);
  packMatrixFp32(W.data(), out, in, P.data());
  int checked = 0;
  for (int s = 0; s < in / 16; ++s)
    for (int b = 0; b < out / 32; ++b)
      for (int c = 0; c < 16; ++c)
        for (int i = 0; i < 32; ++i) {
          const std::size_t at = ((static_cast<std::size_t>(s) * (out / 32) + b) * 16 + c) * 32 + i;
          const int r = 32 * b + i, k = 16 * s + c;
          CHECK(P[at] == static_cast<float>(k * out + r));
          ++checked;
        }
  CHECK(checked == out * in);
  // Columns c0.. (c0 a multiple of 16) start at c0·out, as in W: a head's slice of Wo.
  std::vector<float> slice(static_cast<std::size_t>(out) * 16);
  packMatrixFp32(W.data() + 32 * out, out, 16, slice.data());
  CHECK(std::memcmp(slice.data(), P.data() + 32 * out, slice.size() * sizeof(float)) == 0);
  CHECK_THROWS_AS(packMatrixFp32(W.data(), 48, 32, P.data()), std::invalid_argument);
  CHECK_THROWS_AS(packMatrixFp32(W.data(), 64, 40, P.data()), std::invalid_argument);
  static_assert(packedSupported<SmallPolicyDims>() && packedSupported<PaperPolicyDims>());
  static_assert(!packedSupported<PolicyDims<36, 4, 1, 2, 20, 14, 8>>());
}

TEST_CASE("affineTokensPacked equals affineTokens bit for bit with every kernel; a wrong packing differs") {
  checkPackedShape<32, 32, 5>(1);     // small d_model
  checkPackedShape<64, 32, 5>(2);     // small FFN in
  checkPackedShape<128, 128, 5>(3);   // paper attention
  checkPackedShape<512, 128, 5>(4);   // paper FFN in
  checkPackedShape<128, 512, 5>(5);   // paper FFN out
  checkPackedShape<128, 32, 5>(6);    // a paper head's slice of Wo
  checkPackedShape<96, 48, 3>(7);     // other J, three blocks and strips
}

namespace {

struct Rollout {
  std::vector<float> actions, cross, score, age_profile, cross_out;
};

/// `ticks` steps of random inputs from an empty window: the actions and the attention record.
template <class Dims>
Rollout roll(const PolicyWeights<Dims>& w, std::uint64_t seed, int ticks) {
  auto ws = makePolicyWorkspace<Dims>();
  resetPolicyStream(*ws);
  std::mt19937_64 rng(seed);
  Rollout r;
  const auto append = [](std::vector<float>& v, const auto& record) {
    const auto* p = reinterpret_cast<const float*>(&record);
    v.insert(v.end(), p, p + sizeof(record) / sizeof(float));
  };
  for (int t = 0; t < ticks; ++t) {
    const PolicyInput in = test::randomPolicyInput(rng, t % w.movements, t, 1.2);
    const auto& a = stepPolicy(w, *ws, in);
    r.actions.insert(r.actions.end(), a.data(), a.data() + 5);
    append(r.cross, ws->cross);
    append(r.score, ws->score);
    append(r.age_profile, ws->age_profile);
    append(r.cross_out, ws->cross_out);
  }
  return r;
}

template <class Dims>
void checkPackedStep(std::uint64_t seed, int ticks) {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const test::RandomPolicy p = test::makeRandomPolicy(Dims::arch(), arm, seed);
  PolicyWeights<Dims> w =
      bindPolicyWeights<Dims>(p.pointers.data(), p.pointers.size(), Dims::arch(), Conditioning::kReference,
                              PolicyKernel::kSse);
  const Rollout fp32 = roll(w, seed, ticks);
  // The blob from the file (manifest order) is the views' matrices packed in view order.
  ModelHeader h;
  h.arch = Dims::arch();
  for (int j = 0; j < h.arch.tokens; ++j) h.joints.push_back({"j" + std::to_string(j), -1.0, 1.0, 2.0});
  for (int mv = 0; mv < h.arch.movements; ++mv) h.movement_names.push_back("m" + std::to_string(mv));
  h.metadata_json = "{}";
  const ModelFile file = decodeModel(encodeModel(h, p.tensors), "packed test model");
  const AlignedBytes blob = packModelFp32(file);
  REQUIRE(blob.size == packedPolicyBytes<Dims>());
  REQUIRE(blob.size == packedModelBytes(Dims::arch()));
  const AlignedBytes from_views = packPolicyFp32(w);  // what nao_rt --weights makes
  CHECK(std::memcmp(from_views.data.get(), blob.data.get(), blob.size) == 0);

  bindPackedWeights<Dims>(w, blob.data.get());
  CHECK(usesPacked(w));
  CHECK_FALSE(usesInt8(w));
  for (PolicyKernel k : supportedKernels()) {
    CAPTURE(policyKernelName(k));
    setPolicyKernel(w, k);
    const Rollout packed = roll(w, seed, ticks);
    CHECK(sameBits(packed.actions, fp32.actions));
    CHECK(sameBits(packed.cross, fp32.cross));
    CHECK(sameBits(packed.score, fp32.score));
    CHECK(sameBits(packed.age_profile, fp32.age_profile));
    CHECK(sameBits(packed.cross_out, fp32.cross_out));
  }
  // The packed views are what the step reads: zeroing the blob's copy changes the actions.
  AlignedBytes zeros = packModelFp32(file);
  std::memset(zeros.data.get(), 0, zeros.size);
  bindPackedWeights<Dims>(w, zeros.data.get());
  setPolicyKernel(w, PolicyKernel::kSse);
  CHECK_FALSE(sameBits(roll(w, seed, 4).actions, std::vector<float>(fp32.actions.begin(), fp32.actions.begin() + 20)));
  // int8 replaces them; unbinding leaves the fp32 views.
  const AlignedBytes q = quantizePolicyInt8(w);
  bindQuantizedWeights<Dims>(w, q.data.get());
  CHECK(usesInt8(w));
  CHECK_FALSE(usesPacked(w));
  unbindQuantizedWeights<Dims>(w);
  CHECK_FALSE(usesPacked(w));
  CHECK(sameBits(roll(w, seed, ticks).actions, fp32.actions));
}

}  // namespace

TEST_CASE("stepPolicy with packed fp32 weights: the fp32 bits (actions and attention record) with every kernel") {
  checkPackedStep<SmallPolicyDims>(31, 40);  // window 8: the rings wrap
  checkPackedStep<PaperPolicyDims>(32, 24);  // window 20
}

TEST_CASE("warmPolicy reads each matrix once: the packed copy instead of the view, not both") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const test::RandomPolicy p = test::makeRandomPolicy(SmallPolicyDims::arch(), arm, 33);
  PolicyWeights<SmallPolicyDims> w =
      bindPolicyWeights<SmallPolicyDims>(p.pointers.data(), p.pointers.size(), SmallPolicyDims::arch(),
                                         Conditioning::kReference);
  auto ws = makePolicyWorkspace<SmallPolicyDims>();
  std::size_t fp32 = 0;
  for (const TensorSpec& t : policyManifest(SmallPolicyDims::arch())) fp32 += 4 * t.count();
  std::uint64_t sink = 0;
  CHECK(warmPolicy(w, *ws, sink) == fp32 + sizeof(*ws));
  // The packed blob holds every matrix it replaces once: the same byte count, other addresses.
  const AlignedBytes blob = packPolicyFp32(w);
  bindPackedWeights<SmallPolicyDims>(w, blob.data.get());
  // The blob's lines are what it reads: one byte of it changed changes the sum by as much.
  const std::uint8_t first = blob.data[0];
  const int delta = first < 255 ? 1 : -1;
  std::uint64_t s_before = 0, s_after = 0;
  CHECK(warmPolicy(w, *ws, s_before) == fp32 + sizeof(*ws));
  blob.data[0] = static_cast<std::uint8_t>(first + delta);
  CHECK(warmPolicy(w, *ws, s_after) == fp32 + sizeof(*ws));
  CHECK(static_cast<std::int64_t>(s_after - s_before) == delta);
}
