// The policy kernels (nao/policy_kernels.hpp): the kSse, kAvx2 and kAvx512 implementations of
// affineTokens give bit-identical results, equal bit for bit to a plain scalar loop that sums
// in k order with one rounded multiply and one rounded add per term; and whole stepPolicy runs
// (actions, α, scores, cross_out) are bit-identical under every kernel. On a CPU without AVX2
// (or AVX-512) the other checks still run and a message says which kernel was not available.
#include "nao/policy.hpp"
#include "support/random_policy.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

using namespace nao;

namespace {

float uniform(std::mt19937_64& rng, double lo, double hi) { return test::uniformFloat(rng, lo, hi); }

bool haveAvx2() { return policyKernelSupported(PolicyKernel::kAvx2); }
bool haveAvx512() { return policyKernelSupported(PolicyKernel::kAvx512); }

constexpr PolicyKernel kAllKernels[] = {PolicyKernel::kSse, PolicyKernel::kAvx2, PolicyKernel::kAvx512};

void noteAvx2Absent() {
  if (!haveAvx2()) MESSAGE("AVX2 is not available on this CPU (or build): only the SSE kernel was checked");
  if (!haveAvx512())
    MESSAGE("AVX-512 F/BW/VNNI is not available on this CPU (or build): the avx512 kernel was not checked");
}

bool sameBits(const float* a, const float* b, std::size_t n) { return std::memcmp(a, b, n * sizeof(float)) == 0; }

/// Index of the first float whose bits differ, or -1.
long firstDifference(const float* a, const float* b, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    if (std::memcmp(a + i, b + i, sizeof(float)) != 0) return static_cast<long>(i);
  return -1;
}

/// The definition: Y(r, t) = b(r) + W(r,0) X(0,t) + W(r,1) X(1,t) + ..., summed in k order,
/// each product rounded before it is added (the project builds with -ffp-contract=off).
template <int Out, int In, int J, bool kRelu>
void scalarAffine(const float* W, const float* b, const float* X, float* Y) {
  for (int t = 0; t < J; ++t)
    for (int r = 0; r < Out; ++r) {
      float s = b != nullptr ? b[r] : 0.0f;
      for (int k = 0; k < In; ++k) {
        const float p = W[static_cast<std::ptrdiff_t>(k) * Out + r] * X[t * In + k];
        s = s + p;
      }
      Y[t * Out + r] = kRelu ? std::max(s, 0.0f) : s;
    }
}

/// Values over several binades (a sum of them depends on its order) with some exact zeros.
void fillWide(std::mt19937_64& rng, std::vector<float>& v) {
  for (float& x : v) {
    const int e = static_cast<int>(rng() % 13) - 6;
    x = (rng() % 17 == 0) ? 0.0f : std::ldexp(uniform(rng, -1.0, 1.0), e);
  }
}

template <class Derived>
void fillWide(std::mt19937_64& rng, Eigen::MatrixBase<Derived>& m) {
  std::vector<float> v(static_cast<std::size_t>(m.size()));
  fillWide(rng, v);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.derived().data()[i] = v[static_cast<std::size_t>(i)];
}

/// affineTokens of one shape: kSse, kAvx2 and kAvx512 (if available) against the scalar definition,
/// bit for bit, with and without bias and ReLU, over several random draws.
template <int Out, int In, int J>
void checkShape(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<float> W(static_cast<std::size_t>(Out) * In), b(Out), X(static_cast<std::size_t>(In) * J);
  std::vector<float> want(static_cast<std::size_t>(Out) * J), sse(want.size()), avx(want.size());
  const auto run = [&](auto relu, const float* bias) {
    constexpr bool kRelu = decltype(relu)::value;
    std::fill(sse.begin(), sse.end(), NAN);  // every output is written
    std::fill(avx.begin(), avx.end(), NAN);
    scalarAffine<Out, In, J, kRelu>(W.data(), bias, X.data(), want.data());
    detail::affineTokensSse<Out, In, J, kRelu>(W.data(), bias, X.data(), sse.data());
    INFO("Out ", Out, ", In ", In, ", J ", J, ", relu ", kRelu, ", bias ", bias != nullptr, ", seed ", seed);
    const long d_sse = firstDifference(sse.data(), want.data(), want.size());
    CHECK_MESSAGE(d_sse < 0, "SSE differs from the scalar definition at ", d_sse);
#if NAO_POLICY_HAVE_AVX2
    if (haveAvx2()) {
      detail::affineTokensAvx2<Out, In, J, kRelu>(W.data(), bias, X.data(), avx.data());
      const long d_avx = firstDifference(avx.data(), want.data(), want.size());
      CHECK_MESSAGE(d_avx < 0, "AVX2 differs from the scalar definition at ", d_avx);
    }
    if (haveAvx512()) {
      std::fill(avx.begin(), avx.end(), NAN);
      detail::affineTokensAvx512<Out, In, J, kRelu>(W.data(), bias, X.data(), avx.data());
      const long d_avx = firstDifference(avx.data(), want.data(), want.size());
      CHECK_MESSAGE(d_avx < 0, "AVX-512 differs from the scalar definition at ", d_avx);
    }
#endif
    // Through the dispatcher, every kernel.
    for (PolicyKernel k : kAllKernels) {
      if (!policyKernelSupported(k)) continue;
      std::fill(avx.begin(), avx.end(), NAN);
      detail::affineTokens<Out, In, J, kRelu>(k, W.data(), bias, X.data(), avx.data());
      CHECK_MESSAGE(sameBits(avx.data(), want.data(), want.size()), "affineTokens with ",
                    std::string(policyKernelName(k)));
    }
  };
  for (int draw = 0; draw < 3; ++draw) {
    fillWide(rng, W);
    fillWide(rng, b);
    fillWide(rng, X);
    run(std::false_type{}, b.data());
    run(std::true_type{}, b.data());
    run(std::false_type{}, nullptr);
  }
}

// ---- Whole policies ----

/// Random weights for `arch`: Xavier-uniform matrices, non-zero biases, embeddings, gains and
/// normalisation statistics, so every term of the forward pass reaches the outputs.
std::vector<std::vector<float>> randomTensors(const PolicyArch& arch, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::vector<float>> tensors;
  for (const TensorSpec& s : policyManifest(arch)) {
    std::vector<float> v(s.count());
    const std::string& n = s.name;
    const bool is_std = n.size() > 4 && n.compare(n.size() - 4, 4, "_std") == 0;
    const bool is_gain = n.size() > 5 && n.compare(n.size() - 5, 5, ".gain") == 0;
    for (float& x : v) {
      if (is_std)
        x = uniform(rng, 0.05, 0.5);
      else if (is_gain)
        x = uniform(rng, 0.7, 1.3);
      else if (s.shape.size() == 2 && n.rfind("embed.", 0) != 0 && n != "centroids") {
        const double a = std::sqrt(6.0 / (s.shape[0] + s.shape[1]));
        x = uniform(rng, -a, a);
      } else {
        x = uniform(rng, -0.5, 0.5);
      }
    }
    tensors.push_back(std::move(v));
  }
  return tensors;
}

PolicyInput randomInput(std::mt19937_64& rng, int movement, int step) {
  return test::randomPolicyInput(rng, movement, step, 2.0);
}

/// What a step records, as raw floats: actions, α of every decoder layer, score, cross_out and the chunk.
template <class Dims>
std::vector<float> recordOf(const PolicyWorkspace<Dims>& ws) {
  std::vector<float> r(ws.action.data(), ws.action.data() + ws.action.size());
  const float* cross = &ws.cross[0][0][0][0];
  r.insert(r.end(), cross, cross + sizeof(ws.cross) / sizeof(float));
  r.insert(r.end(), ws.score.data(), ws.score.data() + ws.score.size());
  r.insert(r.end(), ws.mass.data(), ws.mass.data() + ws.mass.size());
  r.insert(r.end(), ws.age_profile.data(), ws.age_profile.data() + ws.age_profile.size());
  r.insert(r.end(), ws.cross_out.data(), ws.cross_out.data() + ws.cross_out.size());
  r.insert(r.end(), ws.chunk.data(), ws.chunk.data() + ws.chunk.size());
  return r;
}

/// For `n_models` random weight sets, both conditioning modes and `n_inputs` random inputs:
/// the step of the weights bound with kSse, with kAvx2 and with kAvx512 records the same bits,
/// the three bindings stepping side by side in one process. Returns the number of steps
/// compared with another kernel (0 without AVX2).
template <class Dims>
int checkStepBitIdentical(std::uint64_t seed, int n_models, int n_inputs, const PolicyArch& arch = Dims::arch()) {
  int compared = 0;
  for (int m = 0; m < n_models; ++m) {
    const std::vector<std::vector<float>> tensors = randomTensors(arch, seed + 100 * static_cast<std::uint64_t>(m));
    std::vector<const float*> ptrs;
    for (const std::vector<float>& t : tensors) ptrs.push_back(t.data());
    for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
      const PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c, PolicyKernel::kSse);
      // Another kernel on a copy of the binding, and one bound with it.
      PolicyWeights<Dims> w_avx = w;
      if (haveAvx2()) setPolicyKernel(w_avx, PolicyKernel::kAvx2);
      const PolicyWeights<Dims> w_avx512 =
          haveAvx512() ? bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c, PolicyKernel::kAvx512) : w;
      REQUIRE(w.kernel == PolicyKernel::kSse);
      // Three streams fed the same inputs in the same order (the window carries history).
      const auto ws_sse = makePolicyWorkspace<Dims>();
      const auto ws_sse2 = makePolicyWorkspace<Dims>();
      const auto ws_avx = makePolicyWorkspace<Dims>();
      const auto ws_avx512 = makePolicyWorkspace<Dims>();
      std::mt19937_64 rng(seed + 7 + static_cast<std::uint64_t>(m));
      for (int n = 0; n < n_inputs; ++n) {
        const PolicyInput in = randomInput(rng, n % arch.movements, (n * 37) % (arch.max_steps + 10));
        stepPolicy(w, *ws_sse, in);
        const std::vector<float> a = recordOf(*ws_sse);
        REQUIRE(ws_sse->action.allFinite());
        // SSE is deterministic on its own: a second stream with the same history gives the same bits.
        stepPolicy(w, *ws_sse2, in);
        CHECK(sameBits(recordOf(*ws_sse2).data(), a.data(), a.size()));
        INFO("model ", m, ", ", conditioningName(c), ", input ", n);
        if (!haveAvx2()) continue;
        stepPolicy(w_avx, *ws_avx, in);
        const std::vector<float> b = recordOf(*ws_avx);
        const long d = firstDifference(a.data(), b.data(), a.size());
        CHECK_MESSAGE(d < 0, "SSE and AVX2 records differ at float ", d, " (0-4 actions, then α, score, mass, age profile, cross_out, chunk, bin)");
        ++compared;
        if (!haveAvx512()) continue;
        stepPolicy(w_avx512, *ws_avx512, in);
        const std::vector<float> e = recordOf(*ws_avx512);
        const long d512 = firstDifference(a.data(), e.data(), a.size());
        CHECK_MESSAGE(d512 < 0, "SSE and AVX-512 records differ at float ", d512, " (0-4 actions, then α, score, mass, age profile, cross_out, chunk, bin)");
      }
    }
  }
  return compared;
}

}  // namespace

TEST_CASE("kernels: SSE always available, AVX2 and AVX-512 when the CPU has them; names parse back") {
  CHECK(policyKernelSupported(PolicyKernel::kSse));
  CHECK(std::string(policyKernelName(PolicyKernel::kSse)) == "sse");
  CHECK(std::string(policyKernelName(PolicyKernel::kAvx2)) == "avx2");
  CHECK(std::string(policyKernelName(PolicyKernel::kAvx512)) == "avx512");
  for (PolicyKernel k : kAllKernels) {
    PolicyKernel parsed = static_cast<PolicyKernel>(-1);
    CHECK(parsePolicyKernel(policyKernelName(k), parsed));
    CHECK(parsed == k);
  }
  PolicyKernel unchanged = PolicyKernel::kAvx2;
  for (const char* bad : {"", "auto", "SSE", "avx", "avx5120", "sse "}) {
    CHECK_FALSE(parsePolicyKernel(bad, unchanged));
    CHECK(unchanged == PolicyKernel::kAvx2);
  }
  // The best is the widest supported, and asking twice gives the same answer (no state).
  const PolicyKernel best = haveAvx512() ? PolicyKernel::kAvx512 : haveAvx2() ? PolicyKernel::kAvx2 : PolicyKernel::kSse;
  CHECK(bestPolicyKernel() == best);
  CHECK(bestPolicyKernel() == bestPolicyKernel());
  if (haveAvx512()) CHECK(haveAvx2());  // its window attention is the AVX2 one
#if !NAO_POLICY_HAVE_AVX2
  CHECK_FALSE(haveAvx2());  // no AVX2 code in a non-x86 build
  CHECK_FALSE(haveAvx512());
#endif
  CHECK_NOTHROW(requirePolicyKernel(PolicyKernel::kSse));
  CHECK_NOTHROW(requirePolicyKernel(best));
  CHECK_THROWS_AS(requirePolicyKernel(static_cast<PolicyKernel>(7)), std::invalid_argument);
  if (!haveAvx512())
    CHECK_THROWS_WITH_AS(requirePolicyKernel(PolicyKernel::kAvx512),
                         doctest::Contains("policy kernel avx512: not supported by this CPU"), std::invalid_argument);
  const std::string what = std::string("kernels: sse yes, avx2 ") + (haveAvx2() ? "yes" : "no") + ", avx512 " +
                           (haveAvx512() ? "yes" : "no") + "; best: " + policyKernelName(bestPolicyKernel());
  MESSAGE(what);
  noteAvx2Absent();
}

TEST_CASE("the kernel is the bound weights': chosen at bind (default the best), checked against the CPU, no environment") {
  using Dims = SmallPolicyDims;
  const PolicyArch arch = Dims::arch();
  const std::vector<std::vector<float>> tensors = randomTensors(arch, 5);
  std::vector<const float*> ptrs;
  for (const std::vector<float>& t : tensors) ptrs.push_back(t.data());
  const Conditioning c = Conditioning::kReference;
  CHECK(PolicyWeights<Dims>{}.kernel == PolicyKernel::kSse);  // unbound: what every CPU runs
  CHECK(bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c).kernel == bestPolicyKernel());
  for (PolicyKernel k : kAllKernels) {
    INFO(policyKernelName(k));
    if (policyKernelSupported(k)) {
      CHECK(bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c, k).kernel == k);
    } else {
      const std::string named = std::string("policy kernel ") + policyKernelName(k);
      CHECK_THROWS_WITH_AS(bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c, k),
                           doctest::Contains(named.c_str()), std::invalid_argument);
    }
  }
  PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c, PolicyKernel::kSse);
  CHECK_THROWS_AS(setPolicyKernel(w, static_cast<PolicyKernel>(7)), std::invalid_argument);
  CHECK(w.kernel == PolicyKernel::kSse);  // unchanged by the refused kernel
  setPolicyKernel(w, bestPolicyKernel());
  CHECK(w.kernel == bestPolicyKernel());
  // NAO_POLICY_KERNEL was once read by the core: it no longer changes anything.
  const char* old = std::getenv("NAO_POLICY_KERNEL");
  const std::string saved = old != nullptr ? old : "";
  setenv("NAO_POLICY_KERNEL", "sse", 1);
  CHECK(bestPolicyKernel() == (haveAvx512() ? PolicyKernel::kAvx512 : haveAvx2() ? PolicyKernel::kAvx2 : PolicyKernel::kSse));
  CHECK(bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c).kernel == bestPolicyKernel());
  if (old != nullptr)
    setenv("NAO_POLICY_KERNEL", saved.c_str(), 1);
  else
    unsetenv("NAO_POLICY_KERNEL");
}

TEST_CASE("affineTokens: SSE and AVX2 equal the scalar k-order definition bit for bit, odd shapes included") {
  // Out not a multiple of 4, 8, 16 or 24; In not a multiple of any panel or strip width.
  checkShape<1, 1, 5>(1);
  checkShape<3, 5, 5>(2);
  checkShape<7, 3, 5>(3);
  checkShape<8, 4, 5>(4);
  checkShape<9, 17, 5>(5);
  checkShape<15, 9, 5>(6);
  checkShape<16, 16, 5>(7);
  checkShape<17, 13, 5>(8);
  checkShape<23, 7, 5>(9);
  checkShape<24, 25, 5>(10);
  checkShape<31, 33, 5>(11);
  checkShape<33, 2, 5>(12);
  checkShape<40, 19, 5>(13);
  checkShape<47, 65, 5>(14);
  checkShape<63, 31, 5>(15);
  checkShape<130, 131, 5>(16);
  // Other token counts.
  checkShape<37, 11, 1>(17);
  checkShape<20, 6, 3>(18);
  checkShape<64, 29, 7>(19);
  // The paper shapes (d 128, FFN 512, head dim 32) and the small ones (d 32, FFN 64).
  checkShape<128, 128, 5>(20);
  checkShape<512, 128, 5>(21);
  checkShape<512, 512, 5>(22);
  checkShape<128, 512, 5>(23);
  checkShape<128, 32, 5>(24);
  checkShape<32, 32, 5>(25);
  checkShape<64, 32, 5>(26);
  checkShape<32, 64, 5>(27);
  noteAvx2Absent();
}

TEST_CASE("the bit-for-bit comparison can fail: another summation order or a fused multiply-add differs") {
  // The inputs of checkShape are wide enough that the order of the sum shows in the bits, so
  // a kernel that reassociated or fused would not pass the test above.
  constexpr int Out = 64, In = 128, J = 5;
  std::mt19937_64 rng(99);
  std::vector<float> W(Out * In), b(Out), X(In * J);
  fillWide(rng, W);
  fillWide(rng, b);
  fillWide(rng, X);
  std::vector<float> want(Out * J), reversed(Out * J), fused(Out * J);
  scalarAffine<Out, In, J, false>(W.data(), b.data(), X.data(), want.data());
  for (int t = 0; t < J; ++t)
    for (int r = 0; r < Out; ++r) {
      float s_rev = b[r], s_fma = b[r];
      for (int k = In - 1; k >= 0; --k) s_rev = s_rev + W[k * Out + r] * X[t * In + k];
      for (int k = 0; k < In; ++k) s_fma = std::fma(W[k * Out + r], X[t * In + k], s_fma);
      reversed[t * Out + r] = s_rev;
      fused[t * Out + r] = s_fma;
    }
  CHECK_FALSE(sameBits(reversed.data(), want.data(), want.size()));
  CHECK_FALSE(sameBits(fused.data(), want.data(), want.size()));
}

/// The window-attention kernels against the Eigen code they replaced (policy.hpp before the
/// transposed key ring): per key, q.segment<Dh>(c0).dot(K.col(key).segment<Dh>(c0)) · scale, and
/// o.segment<Dh>(c0) += α · V.col(key).segment<Dh>(c0) newest tick first. Bit for bit, both kernels.
template <int D, int H, int J, int W>
void checkWindowKernels(std::uint64_t seed) {
  constexpr int Dh = D / H, N = W * J;
  constexpr int NP = (N + detail::kKeyRowBlock - 1) / detail::kKeyRowBlock * detail::kKeyRowBlock;
  static_assert(detail::kWindowKernelExact<Dh>);
  std::mt19937_64 rng(seed);
  Eigen::Matrix<float, D, J> q;
  Eigen::Matrix<float, D, N> K, V;
  fillWide(rng, q);
  fillWide(rng, K);
  fillWide(rng, V);
  Eigen::Matrix<float, NP, D> KT = Eigen::Matrix<float, NP, D>::Zero();
  KT.template topRows<N>() = K.transpose();
  const float scale = 1.0f / std::sqrt(static_cast<float>(Dh));
  float alpha[N];
  for (float& a : alpha) a = uniform(rng, 0.0, 1.0);
  for (PolicyKernel k : kAllKernels) {
    if (!policyKernelSupported(k)) continue;
    for (int n : {1, W / 2, W})
      for (int slot : {0, n - 1, W - 1}) {
        if (n < W && slot != n - 1) continue;  // before the ring wraps, the newest tick is slot n − 1
        const int rows = (n * J + detail::kKeyRowBlock - 1) / detail::kKeyRowBlock * detail::kKeyRowBlock;
        for (int hd = 0; hd < H; ++hd)
          for (int i = 0; i < J; ++i) {
            const int c0 = hd * Dh;
            alignas(32) float got[NP];
            detail::windowScores<Dh, NP>(k, q.col(i).data() + c0, KT.data() + c0 * NP, rows, scale, got);
            for (int key = 0; key < n * J; ++key) {
              const float want = q.col(i).template segment<Dh>(c0).dot(K.col(key).template segment<Dh>(c0)) * scale;
              REQUIRE_MESSAGE(std::memcmp(&want, &got[key], sizeof(float)) == 0,
                              policyKernelName(k) << " Dh " << Dh << " key " << key << ": " << got[key] << " vs " << want);
            }
            // The J queries of a head in one call: each the bits of the per-key dot too.
            if (i == 0) {
              alignas(64) float got_q[J][NP];
              detail::windowScoresQueries<Dh, NP, J>(k, q.data() + c0, D, KT.data() + c0 * NP, rows, scale, got_q[0],
                                                     NP);
              for (int iq = 0; iq < J; ++iq)
                for (int key = 0; key < n * J; ++key) {
                  const float want = q.col(iq).template segment<Dh>(c0).dot(K.col(key).template segment<Dh>(c0)) * scale;
                  REQUIRE_MESSAGE(std::memcmp(&want, &got_q[iq][key], sizeof(float)) == 0,
                                  policyKernelName(k) << " Dh " << Dh << " query " << iq << " of " << J << " key " << key);
                }
            }
            Eigen::Matrix<float, Dh, 1> want_o = Eigen::Matrix<float, Dh, 1>::Zero();
            for (int age = 0; age < n; ++age)
              for (int j = 0; j < J; ++j)
                want_o += alpha[age * J + j] * V.col(((slot - age + W) % W) * J + j).template segment<Dh>(c0);
            float got_o[Dh];
            detail::windowValues<Dh, J, W>(k, alpha, V.data() + c0, D, slot, n, got_o);
            REQUIRE_MESSAGE(sameBits(want_o.data(), got_o, Dh), policyKernelName(k) << " values, Dh " << Dh);
          }
      }
  }
}

TEST_CASE("window attention kernels: scores and value sums equal the per-key Eigen code bit for bit (SSE, AVX2)") {
  checkWindowKernels<128, 4, 5, 20>(31);  // paper: head dim 32, 100 keys in 104 rows
  checkWindowKernels<32, 4, 5, 8>(32);    // small: head dim 8, 40 keys
  checkWindowKernels<64, 4, 5, 3>(33);    // head dim 16, 15 keys in 16 rows
  noteAvx2Absent();
}

/// windowSoftmax under every kernel against its scalar form under SSE (the code it was taken
/// from), bit for bit: α of every query and key, the zeros past the window included.
template <int J, int W>
void checkWindowSoftmax(std::uint64_t seed) {
  constexpr int N = W * J, NP = (N + detail::kKeyRowBlock - 1) / detail::kKeyRowBlock * detail::kKeyRowBlock;
  std::mt19937_64 rng(seed);
  for (int draw = 0; draw < 40; ++draw) {
    alignas(64) float raw[J][NP];
    float bias[W];
    for (auto& row : raw)
      for (float& x : row) x = uniform(rng, -6.0, 6.0);
    for (float& b : bias) b = uniform(rng, -1.0, 1.0);
    if (draw % 4 == 1) {  // a zero maximum: −0 then +0 (the sequential max keeps the first)
      for (auto& row : raw)
        for (float& x : row) x = uniform(rng, -6.0, -0.5);
      for (float& b : bias) b = 0.0f;
      raw[0][3] = -0.0f;
      raw[0][7] = 0.0f;
      raw[1][2] = 0.0f;
    }
    if (draw % 4 == 2) {  // non-finite scores
      raw[0][1] = std::numeric_limits<float>::quiet_NaN();
      raw[1][4] = -std::numeric_limits<float>::infinity();
      for (float& x : raw[2]) x = std::numeric_limits<float>::quiet_NaN();
    }
    const int n = 1 + static_cast<int>(rng() % W), slot = n < W ? n - 1 : static_cast<int>(rng() % W);
    float want[J][N];
    std::fill(&want[0][0], &want[0][0] + J * N, 1.0f);
    detail::windowSoftmaxScalar<J, W, NP, N>(PolicyKernel::kSse, raw[0], bias, slot, n, want[0]);
    for (PolicyKernel k : kAllKernels) {
      if (!policyKernelSupported(k)) continue;
      float got[J][N];
      std::fill(&got[0][0], &got[0][0] + J * N, 1.0f);
      detail::windowSoftmax<J, W, NP, N>(k, raw[0], bias, slot, n, got[0]);
      for (int i = 0; i < J; ++i)
        for (int m = 0; m < N; ++m) {
          INFO(policyKernelName(k), " draw ", draw, " n ", n, " query ", i, " key ", m);
          if (std::isnan(want[i][m]))
            CHECK(std::isnan(got[i][m]));
          else
            CHECK(sameBits(&got[i][m], &want[i][m], 1));
        }
    }
  }
}

TEST_CASE("windowSoftmax: every kernel gives the bits of the scalar softmax (zero maxima, NaN, short windows)") {
  checkWindowSoftmax<5, 20>(41);  // paper: 100 keys
  checkWindowSoftmax<5, 3>(42);   // 15 keys: one partial register
  checkWindowSoftmax<3, 7>(43);
}

TEST_CASE("the window score comparison can fail: a plain k-order dot differs from Eigen's on these inputs") {
  constexpr int Dh = 32, N = 100;
  std::mt19937_64 rng(31);
  Eigen::Matrix<float, Dh, N> K;
  Eigen::Matrix<float, Dh, 1> q;
  fillWide(rng, q);
  fillWide(rng, K);
  int differ = 0;
  for (int key = 0; key < N; ++key) {
    float plain = 0.0f;
    for (int d = 0; d < Dh; ++d) plain = plain + q[d] * K(d, key);
    const float eigen = q.dot(K.col(key));
    differ += std::memcmp(&plain, &eigen, sizeof(float)) != 0;
  }
  CHECK(differ > N / 4);
}

TEST_CASE("stepPolicy records the same bits under SSE and AVX2: small dims, many weights and inputs") {
  const int compared = checkStepBitIdentical<SmallPolicyDims>(1000, 8, 60);
  CHECK(compared == (haveAvx2() ? 8 * 2 * 60 : 0));
  noteAvx2Absent();
}

TEST_CASE("stepPolicy records the same bits under SSE and AVX2: paper dims") {
  const int compared = checkStepBitIdentical<PaperPolicyDims>(2000, 3, 20);
  CHECK(compared == (haveAvx2() ? 3 * 2 * 20 : 0));
  noteAvx2Absent();
}

TEST_CASE("stepPolicy records the same bits under SSE and AVX2: odd dims (leftover rows and columns)") {
  using Odd = PolicyDims<36, 4, 1, 2, 20, 13, 7>;
  PolicyArch arch = Odd::arch();
  arch.movements = 2;
  arch.clusters = 4;
  arch.max_steps = 16;
  const int compared = checkStepBitIdentical<Odd>(3000, 4, 40, arch);
  CHECK(compared == (haveAvx2() ? 4 * 2 * 40 : 0));
  noteAvx2Absent();
}

TEST_CASE("stepPolicy records the same bits under SSE and AVX2: a chunk of 3 (the whole chunk too)") {
  PolicyArch arch = SmallPolicyDims::arch();
  arch.chunk = 3;
  const int compared = checkStepBitIdentical<SmallPolicyDims>(4000, 2, 40, arch);
  CHECK(compared == (haveAvx2() ? 2 * 2 * 40 : 0));
  noteAvx2Absent();
}

TEST_CASE("expSoftmax: within 2 ulp of std::exp on [-87, 0], 0 below, NaN kept; every lane width the same bits") {
  // Dense over the softmax's domain (x = score − max score <= 0) plus its edges.
  std::vector<float> xs;
  for (int i = 0; i <= 400000; ++i) xs.push_back(-87.0f * static_cast<float>(i) / 400000.0f);
  for (float x : {0.0f, -0.0f, -1e-30f, -1e-7f, -0.34657359f, -0.6931472f, -86.99f, -87.0f, -87.0001f, -88.0f, -100.0f,
                  -1e30f, -std::numeric_limits<float>::infinity()})
    xs.push_back(x);
  double worst_ulp = 0.0;
  for (float x : xs) {
    const float got = detail::expSoftmax(x);
    if (x < -87.0f) {
      CHECK(got == 0.0f);
      continue;
    }
    const double want = std::exp(static_cast<double>(x));
    const double ulp = std::ldexp(1.0, std::ilogb(static_cast<float>(want)) - 23);
    worst_ulp = std::max(worst_ulp, std::fabs(static_cast<double>(got) - want) / ulp);
  }
  MESSAGE("expSoftmax: worst error " << worst_ulp << " ulp over " << xs.size() << " points");
  CHECK(worst_ulp <= 2.0);
  CHECK(std::isnan(detail::expSoftmax(std::numeric_limits<float>::quiet_NaN())));
  // expShifted under every kernel: the scalar definition's bits in every lane and in the tails.
  std::mt19937_64 rng(77);
  std::vector<float> base(103);
  for (float& v : base) v = uniform(rng, -40.0, 3.0);
  base[7] = std::numeric_limits<float>::quiet_NaN();
  base[20] = -std::numeric_limits<float>::infinity();
  const float shift = 3.0f;
  for (PolicyKernel k : kAllKernels) {
    if (!policyKernelSupported(k)) continue;
    for (int count : {103, 96, 17, 3}) {
      std::vector<float> s = base;
      detail::expShifted(k, s.data(), count, shift);
      for (int m = 0; m < 103; ++m) {
        const float want = m < count ? detail::expSoftmax(base[static_cast<std::size_t>(m)] - shift) : base[static_cast<std::size_t>(m)];
        INFO(policyKernelName(k), " count ", count, " m ", m);
        if (std::isnan(want))
          CHECK(std::isnan(s[static_cast<std::size_t>(m)]));
        else
          CHECK(sameBits(&s[static_cast<std::size_t>(m)], &want, 1));
      }
    }
  }
}

TEST_CASE("headSumNorm: SSE and AVX-512 equal the 16-lane definition bit for bit and Eigen's norm to float rounding") {
  constexpr int D = 128, H = 4;
  std::mt19937_64 rng(91);
  for (int draw = 0; draw < 200; ++draw) {
    std::vector<float> fv(static_cast<std::size_t>(D) * H);
    for (float& v : fv) v = uniform(rng, -2.0, 2.0);
    float a[H];
    for (float& v : a) v = uniform(rng, 0.0, 1.0);
    const float* f[H];
    for (int h = 0; h < H; ++h) f[h] = fv.data() + h * D;
    const float want = detail::headSumNormScalar<D, H>(a, f);
    Eigen::Matrix<float, D, 1> c = Eigen::Matrix<float, D, 1>::Zero();
    for (int h = 0; h < H; ++h) c += a[h] * Eigen::Map<const Eigen::Matrix<float, D, 1>>(f[h]);
    CHECK(want == doctest::Approx(c.norm()).epsilon(1e-6));
#if defined(__SSE2__)
    const float sse = detail::headSumNormSse<D, H>(a, f);
    CHECK(sameBits(&sse, &want, 1));
#endif
#if NAO_POLICY_HAVE_AVX2
    if (haveAvx512()) {
      const float v512 = detail::headSumNormAvx512<D, H>(a, f);
      CHECK(sameBits(&v512, &want, 1));
    }
#endif
    for (PolicyKernel k : kAllKernels) {
      if (!policyKernelSupported(k)) continue;
      const float got = detail::headSumNorm<D, H>(k, a, f);
      CHECK(sameBits(&got, &want, 1));
    }
  }
}

TEST_CASE("headSumNorms: J coefficient sets over the same vectors, each the bits of its own headSumNorm") {
  constexpr int D = 128, H = 4, Q = 5;
  std::mt19937_64 rng(92);
  for (int draw = 0; draw < 50; ++draw) {
    std::vector<float> fv(static_cast<std::size_t>(D) * H);
    for (float& v : fv) v = uniform(rng, -2.0, 2.0);
    float a[Q * H];
    for (float& v : a) v = uniform(rng, 0.0, 1.0);
    const float* f[H];
    for (int h = 0; h < H; ++h) f[h] = fv.data() + h * D;
    float want[Q];
    for (int i = 0; i < Q; ++i) want[i] = detail::headSumNormScalar<D, H>(a + i * H, f);
    CHECK(want[0] != want[1]);  // the sets differ, so a mixed-up index would show
    for (PolicyKernel k : kAllKernels) {
      if (!policyKernelSupported(k)) continue;
      float got[Q];
      std::fill(got, got + Q, NAN);
      detail::headSumNorms<D, H, Q>(k, a, f, got);
      CHECK(sameBits(got, want, Q));
    }
  }
}
