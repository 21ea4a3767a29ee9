// Parity: the runtime's streaming fixed-size float inference (nao/policy.hpp: one tick at a time,
// key/value rings of W ticks) and libtorch's whole-sequence forward of the training module
// (toolchain/src/torch/: all T·J tokens at once under the sliding-window mask) agree within 1e-5
// absolute on the actions, on every decoder layer's cross-attention per body part, on the raw
// mass and the temporal profile, and (relative) on the norm-based score, at every tick of
// sequences several windows long (the ring wraps), random and recorded, for the small
// configuration (fresh weights, perturbed away from their initialisation) and the paper
// configuration (the committed models).
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/reference_source.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "nao/model_metadata.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

using namespace nao;

namespace {

constexpr double kTolerance = 1e-5;

// One rollout's inputs, tick 0 first (movement fixed, step = tick).
using Sequence = std::vector<PolicyInput>;

float uniform(std::mt19937_64& rng, double lo, double hi) {
  return static_cast<float>(lo + (hi - lo) * static_cast<double>(rng() >> 11) * 0x1.0p-53);
}

// Random sequences over the arm's range: q a random walk inside the limits, a(t-1) up to 0.2 rad,
// r (the offset f(t+1) − q(t)) jumping within ±0.2 rad, every movement; `ticks` long.
std::vector<Sequence> randomSequences(const ArmModel& arm, int movements, int count, int ticks, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Sequence> out;
  for (int n = 0; n < count; ++n) {
    Sequence s;
    PolicyInput x;
    for (int j = 0; j < kNumJoints; ++j) {
      x.q[j] = uniform(rng, arm.q_min[j], arm.q_max[j]);
      x.r[j] = uniform(rng, -0.2, 0.2);  // r is the offset f(t+1) − q(t) (docs/policy.md)
    }
    x.movement = n % movements;
    for (int t = 0; t < ticks; ++t) {
      for (int j = 0; j < kNumJoints; ++j) {
        x.a_prev[j] = t == 0 ? 0.0f : uniform(rng, -0.2, 0.2);
        x.q[j] = std::clamp(x.q[j] + x.a_prev[j], static_cast<float>(arm.q_min[j]), static_cast<float>(arm.q_max[j]));
        if (rng() % 8 == 0) x.r[j] = uniform(rng, -0.2, 0.2);
      }
      x.step = t;
      s.push_back(x);
    }
    out.push_back(s);
  }
  return out;
}

// Recorded sequences: the states a policy sees on held-out synthetic demonstrations (triangulated,
// retargeted, feature-extracted with `centroids`), at most `ticks` long.
std::vector<Sequence> recordedSequences(const ArmModel& arm, const std::vector<std::vector<JointVector>>& centroids,
                                        int count, int ticks) {
  std::vector<Sequence> out;
  const tools::Movement movements[3] = {tools::Movement::kElbow, tools::Movement::kWholeArm, tools::Movement::kWrist};
  for (int index = 0; index < count; ++index) {
    const int m = index % 3;  // model movement index: elbow 0, whole_arm 1, wrist 2
    const tools::ReferenceStream ref =
        tools::makeSyntheticReference(arm, movements[m], 77, index, centroids[static_cast<std::size_t>(m)]);
    Sequence s;
    for (std::size_t t = 0; t + 1 < ref.target.size() && static_cast<int>(t) < ticks; ++t) {
      PolicyInput x;
      x.q = ref.target[t].cast<float>();
      x.a_prev = (t == 0 ? JointVector::Zero() : JointVector(ref.target[t] - ref.target[t - 1])).cast<float>();
      // The reference input: the offset of the next feature-extracted pose (docs/policy.md).
      x.r = JointVector(ref.target[t + 1] - ref.target[t]).cast<float>();
      x.movement = m;
      x.step = static_cast<int>(t);
      s.push_back(x);
    }
    out.push_back(s);
  }
  return out;
}

// [1,T,J] of the sequence's q (0), a(t-1) (1) or r (2).
torch::Tensor stack(const Sequence& in, int what) {
  torch::Tensor t = torch::empty({1, static_cast<long>(in.size()), kNumJoints}, torch::kFloat);
  auto a = t.accessor<float, 3>();
  for (std::size_t n = 0; n < in.size(); ++n)
    for (int j = 0; j < kNumJoints; ++j) {
      const PolicyInput& x = in[n];
      a[0][static_cast<long>(n)][j] = what == 0 ? x.q[j] : what == 1 ? x.a_prev[j] : x.r[j];
    }
  return t;
}

template <class Dims>
void checkParity(const tools::PolicyNet& net, const PolicyWeights<Dims>& weights, const std::vector<Sequence>& seqs,
                 const std::string& what) {
  torch::NoGradGuard no_grad;
  auto ws = makePolicyWorkspace<Dims>();
  double worst_action = 0.0, worst_alpha = 0.0, worst_mass = 0.0, worst_profile = 0.0, worst_score_rel = 0.0;
  double largest_action = 0.0, oldest_mass = 0.0;
  long ticks = 0;
  for (const Sequence& seq : seqs) {
    tools::PolicyAttention att;
    const torch::Tensor actions =
        net->act(stack(seq, 0), stack(seq, 1), stack(seq, 2), torch::tensor({static_cast<long>(seq.front().movement)}),
                 &att)
            .contiguous();
    auto ta = actions.accessor<float, 3>();
    std::vector<torch::Tensor> cross;
    for (const torch::Tensor& c : att.cross) cross.push_back(c.contiguous());
    const torch::Tensor mass = att.mass.contiguous(), profile = att.age_profile.contiguous(), score = att.score.contiguous();
    auto tm = mass.accessor<float, 3>();
    auto tp = profile.accessor<float, 3>();
    auto ts = score.accessor<float, 3>();
    resetPolicyStream(*ws);
    for (std::size_t n = 0; n < seq.size(); ++n) {
      const long t = static_cast<long>(n);
      const auto& a = stepPolicy(weights, *ws, seq[n]);
      for (int j = 0; j < kNumJoints; ++j) {
        worst_action = std::max(worst_action, std::abs(static_cast<double>(a[j]) - ta[0][t][j]));
        largest_action = std::max(largest_action, std::abs(static_cast<double>(a[j])));
        worst_mass = std::max(worst_mass, std::abs(static_cast<double>(ws->mass[j]) - tm[0][t][j]));
        const double s_torch = ts[0][t][j];
        worst_score_rel = std::max(worst_score_rel, std::abs(ws->score[j] - s_torch) / std::max(1.0, std::abs(s_torch)));
      }
      for (int age = 0; age < Dims::kWindow; ++age)
        worst_profile = std::max(worst_profile, std::abs(static_cast<double>(ws->age_profile[age]) - tp[0][t][age]));
      if (static_cast<int>(n) >= Dims::kWindow - 1) oldest_mass = std::max(oldest_mass, static_cast<double>(ws->age_profile[Dims::kWindow - 1]));
      for (int l = 0; l < Dims::kDecoderLayers; ++l) {
        auto c = cross[static_cast<std::size_t>(l)].accessor<float, 5>();
        for (int h = 0; h < Dims::kHeads; ++h)
          for (int i = 0; i < kNumJoints; ++i)
            for (int j = 0; j < kNumJoints; ++j)
              worst_alpha = std::max(worst_alpha, std::abs(static_cast<double>(ws->cross[l][h][i][j]) - c[0][t][h][i][j]));
      }
      ++ticks;
    }
  }
  MESSAGE(what << ": " << ticks << " ticks in " << seqs.size() << " sequences; worst |action difference| " << worst_action
               << " rad (largest action " << largest_action << " rad), worst |alpha difference| " << worst_alpha
               << ", |mass difference| " << worst_mass << ", |profile difference| " << worst_profile
               << ", relative score difference " << worst_score_rel);
  CHECK(worst_action <= kTolerance);
  CHECK(worst_alpha <= kTolerance);
  CHECK(worst_mass <= kTolerance);
  CHECK(worst_profile <= kTolerance);
  CHECK(worst_score_rel <= kTolerance);
  // The comparison is not vacuous: the actions vary, and the oldest tick of a full window is
  // attended (the ring wrapped and its far end is read).
  CHECK(largest_action > 1e-3);
  CHECK(oldest_mass > 1e-6);
}

// Loads model.bin tensors into a freshly built torch module of the same architecture.
void loadInto(tools::PolicyNet& net, const ModelFile& model) {
  torch::NoGradGuard no_grad;
  const auto tensors = tools::manifestTensors(net);
  REQUIRE(tensors.size() == model.tensors.size());
  for (std::size_t i = 0; i < tensors.size(); ++i) {
    const torch::Tensor src =
        torch::from_blob(const_cast<float*>(model.data(i)), {static_cast<long>(model.tensors[i].spec.count())},
                         torch::kFloat)
            .clone();
    torch::Tensor dst = tensors[i].second;
    REQUIRE(dst.numel() == src.numel());
    dst.view({-1}).copy_(src);
  }
}

// The metadata's linear AR base as the trainer holds it (per movement; empty: none).
std::vector<tools::LinearArModel> linearArModels(const LinearArCoefficients& k) {
  std::vector<tools::LinearArModel> out;
  for (std::size_t m = 0; m < k.c.size(); ++m) {
    tools::LinearArModel model;
    for (std::size_t j = 0; j < 5; ++j) {
      tools::LinearArJoint& x = model.joints[j];
      x.c = k.c[m][j];
      x.beta = k.beta[m][j];
      x.alpha.clear();
      for (std::size_t i = 0; i < static_cast<std::size_t>(kPolicyArMaxOrder); ++i) x.alpha.push_back(k.alpha[m][i][j]);
      x.order = kPolicyArMaxOrder;
    }
    out.push_back(model);
  }
  return out;
}

std::vector<const float*> pointers(const std::vector<std::vector<float>>& floats) {
  std::vector<const float*> p;
  for (const auto& f : floats) p.push_back(f.data());
  return p;
}

}  // namespace

TEST_CASE("small configuration: streaming runtime inference equals libtorch's whole-sequence forward within 1e-5 (random and recorded rollouts, both modes)") {
  torch::set_num_threads(1);
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  // Key poses: k-means++ of the retargeted poses of one held-out demonstration per movement.
  std::vector<std::vector<JointVector>> centroids;
  {
    const tools::Movement ms[3] = {tools::Movement::kElbow, tools::Movement::kWholeArm, tools::Movement::kWrist};
    for (tools::Movement m : ms) {
      std::vector<JointVector> provisional(10, JointVector::Zero());
      for (int k = 0; k < 10; ++k) provisional[static_cast<std::size_t>(k)][0] = -2.0 + 0.4 * k;
      const tools::ReferenceStream ref = tools::makeSyntheticReference(arm, m, 55, 0, provisional);
      tools::KMeansOptions options;
      centroids.push_back(tools::kmeansPlusPlus(ref.retargeted, options).centroids);
    }
  }
  // Longer than W (8) several times over: the ring wraps; steps run past nothing (T < max_steps).
  const std::vector<Sequence> recorded = recordedSequences(arm, centroids, 6, 200);
  const std::vector<Sequence> random = randomSequences(arm, 3, 6, 3 * smallArch().window + 5, 12);

  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    torch::manual_seed(21);
    tools::PolicyNet net(smallArch(), c);
    {
      // Away from the initialisation (LN gains 1, biases 0, zero step rows) so every term counts.
      torch::NoGradGuard no_grad;
      for (torch::Tensor& p : net->trainableParameters()) p.add_(torch::randn_like(p) * 0.05);
      tools::NormStats stats;
      for (int j = 0; j < kNumJoints; ++j) {
        stats.q_mean[j] = 0.1 * j;
        stats.q_std[j] = 0.5 + 0.1 * j;
        stats.a_mean[j] = 0.001 * j;
        stats.a_std[j] = 0.02 + 0.01 * j;
        stats.r_mean[j] = -0.1 * j;
        stats.r_std[j] = 0.7;
      }
      net->setNormalisation(stats);
      net->setCentroids(centroids);
    }
    const std::vector<std::vector<float>> floats = tools::manifestFloats(net);
    const std::vector<const float*> p = pointers(floats);
    PolicyWeights<SmallPolicyDims> weights = bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), c);
    // A residual gain (reference mode adds g·r to the action; autonomous mode ignores it): both
    // sides must add it in the same place and precision.
    net->residual_gain = 1.0894;
    weights.residual_gain = 1.0894f;
    // A linear AR base (autonomous mode adds it; reference mode ignores it): per movement and
    // joint, orders 1..12, a mean-reverting β, the past actions' weights decaying.
    {
      std::mt19937_64 rng(5);
      std::vector<tools::LinearArModel> ar(3);
      for (std::size_t m = 0; m < 3; ++m)
        for (std::size_t j = 0; j < 5; ++j) {
          tools::LinearArJoint& x = ar[m].joints[j];
          x.order = static_cast<int>(1 + (3 * m + j) % 12);
          x.c = uniform(rng, -0.02, 0.02);
          x.beta = uniform(rng, -0.1, 0.0);
          x.alpha.clear();
          for (int k = 0; k < x.order; ++k) x.alpha.push_back(uniform(rng, -0.9, 0.9) / static_cast<float>(1 + k));
        }
      net->setLinearAr(ar);
      weights.linear_ar = linearArBase<SmallPolicyDims::kMovements>(tools::linearArCoefficients(ar));
      REQUIRE(weights.linear_ar.on);
    }
    const std::string mode = conditioningName(c);
    checkParity(net, weights, random, "small/" + mode + "/random");
    checkParity(net, weights, recorded, "small/" + mode + "/recorded");
  }
}

TEST_CASE("paper configuration: the committed models agree with libtorch within 1e-5") {
  torch::set_num_threads(1);
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const std::filesystem::path models = std::filesystem::path(NAO_TEST_DATA_DIR).parent_path().parent_path() / "models";
  int checked = 0;
  for (const char* name : {"default.bin", "autonomous.bin"}) {
    const std::filesystem::path path = models / name;
    INFO("model " << path.string());
    REQUIRE_MESSAGE(std::filesystem::exists(path), "the committed model is missing");
    const ModelFile model = readModelFile(path.string());
    checkJointsMatch(model, arm, path.string());
    checkPolicyArch<PaperPolicyDims>(model.header.arch);
    tools::PolicyNet net(paperArch(), model.header.conditioning);
    loadInto(net, model);
    std::vector<const float*> p;
    for (std::size_t i = 0; i < model.tensors.size(); ++i) p.push_back(model.data(i));
    PolicyWeights<PaperPolicyDims> weights =
        bindPolicyWeights<PaperPolicyDims>(p.data(), p.size(), model.header.conditioning);
    weights.residual_gain = modelResidualGain(model.header.metadata_json, path.string());
    net->residual_gain = weights.residual_gain;
    const LinearArCoefficients ar = modelLinearAr(model.header.metadata_json, 3, path.string());
    weights.linear_ar = linearArBase<PaperPolicyDims::kMovements>(ar);
    net->setLinearAr(linearArModels(ar));
    std::vector<std::vector<JointVector>> centroids(3);
    for (int m = 0; m < 3; ++m)
      for (int k = 0; k < PaperPolicyDims::kClusters; ++k)
        centroids[static_cast<std::size_t>(m)].push_back(centroid(weights, m, k).cast<double>());
    // 60 ticks = 3 windows (the whole-sequence record needs (T·J)² · d floats: kept short).
    checkParity(net, weights, randomSequences(arm, 3, 3, 60, 13), std::string(name) + "/random");
    checkParity(net, weights, recordedSequences(arm, centroids, 3, 60), std::string(name) + "/recorded");
    ++checked;
  }
  CHECK(checked == 2);
}
