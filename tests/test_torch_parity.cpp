// Parity: the runtime's streaming fixed-size float inference (nao/policy.hpp: one tick at a time,
// key/value rings of W ticks, the chunk ring of C ticks) and libtorch's whole-sequence forward of
// the training module (toolchain/src/torch/: all T·J tokens at once under the sliding-window mask;
// PolicyNet::act) agree within 1e-5 absolute on the executed actions and the network's share of
// them, on each tick's chunk, on every decoder layer's cross-attention per body part, on the raw
// mass and the temporal profile, and (relative) on the norm-based score, at every tick of
// sequences several windows long (the rings wrap), random and recorded, in both conditionings
// (reference mode with a law), for a chunk of 1 and of 5 with the temporal ensemble, in the small
// configuration and the paper one (fresh weights, perturbed away from their initialisation).
#include "nao/policy.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/reference_source.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "support/test_util.hpp"
#include "support/torch_policy.hpp"

#include <doctest/doctest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>
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

// [1,T,J] normalised with the net's norm.* buffers, as act() normalises (rn of the reference).
tools::PolicyBatch normalised(const tools::PolicyNet& net, const Sequence& seq) {
  tools::PolicyBatch b;
  b.qn = (stack(seq, 0) - net->q_mean) / net->q_std;
  b.an = (stack(seq, 1) - net->a_mean) / net->a_std;
  b.rn = (stack(seq, 2) - net->r_mean) / net->r_std;
  b.movement = torch::tensor({static_cast<long>(seq.front().movement)});
  return b;
}

template <class Dims>
void checkParity(const tools::PolicyNet& net, const PolicyWeights<Dims>& weights, const std::vector<Sequence>& seqs,
                 const std::string& what) {
  torch::NoGradGuard no_grad;
  auto ws = makePolicyWorkspace<Dims>();
  const int C = weights.chunk;
  REQUIRE(net->arch().chunk == C);
  double worst_action = 0.0, worst_net = 0.0, worst_chunk = 0.0, worst_alpha = 0.0, worst_mass = 0.0;
  double worst_profile = 0.0, worst_score_rel = 0.0, largest_action = 0.0, oldest_mass = 0.0, largest_law = 0.0;
  long ticks = 0;
  for (const Sequence& seq : seqs) {
    tools::PolicyAttention att;
    torch::Tensor net_action;
    const torch::Tensor actions = net->act(stack(seq, 0), stack(seq, 1), stack(seq, 2),
                                           torch::tensor({static_cast<long>(seq.front().movement)}), &att, &net_action)
                                      .contiguous();
    net_action = net_action.contiguous();
    // Each tick's chunk in rad.
    const tools::PolicyHeadOutput out = net->forward(normalised(net, seq));
    const torch::Tensor chunk =
        (out.chunk * net->a_std.view({1, 1, -1, 1}) + net->a_mean.view({1, 1, -1, 1})).contiguous();
    auto ta = actions.accessor<float, 3>();
    auto tn = net_action.accessor<float, 3>();
    auto tc = chunk.accessor<float, 4>();
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
        worst_net = std::max(worst_net, std::abs(static_cast<double>(ws->net_action[j]) - tn[0][t][j]));
        largest_action = std::max(largest_action, std::abs(static_cast<double>(a[j])));
        largest_law = std::max(largest_law, std::abs(static_cast<double>(a[j]) - ws->net_action[j]));
        for (int c = 0; c < C; ++c)
          worst_chunk = std::max(worst_chunk, std::abs(static_cast<double>(ws->chunk(j, c)) - tc[0][t][j][c]));
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
               << " rad (largest action " << largest_action << " rad, law up to " << largest_law << " rad), net action "
               << worst_net << ", chunk " << worst_chunk << ", worst |alpha difference| " << worst_alpha
               << ", |mass difference| " << worst_mass << ", |profile difference| " << worst_profile
               << ", relative score difference " << worst_score_rel);
  CHECK(worst_action <= kTolerance);
  CHECK(worst_net <= kTolerance);
  CHECK(worst_chunk <= kTolerance);
  CHECK(worst_alpha <= kTolerance);
  CHECK(worst_mass <= kTolerance);
  CHECK(worst_profile <= kTolerance);
  CHECK(worst_score_rel <= kTolerance);
  // The comparison is not vacuous: the actions vary, and the oldest tick of a full window is
  // attended (the ring wrapped and its far end is read); reference mode's law acts.
  CHECK(largest_action > 1e-3);
  CHECK(oldest_mass > 1e-6);
  if (net->conditioning() == Conditioning::kReference) CHECK(largest_law > 1e-3);
  if (net->conditioning() == Conditioning::kAutonomous) CHECK(largest_law == 0.0);
}

std::vector<const float*> pointers(const std::vector<std::vector<float>>& floats) {
  std::vector<const float*> p;
  for (const auto& f : floats) p.push_back(f.data());
  return p;
}

// Key poses: k-means++ of the retargeted poses of one held-out demonstration per movement.
std::vector<std::vector<JointVector>> syntheticKeyPoses(const ArmModel& arm) {
  std::vector<std::vector<JointVector>> centroids;
  const tools::Movement ms[3] = {tools::Movement::kElbow, tools::Movement::kWholeArm, tools::Movement::kWrist};
  for (tools::Movement m : ms) {
    std::vector<JointVector> provisional(10, JointVector::Zero());
    for (int k = 0; k < 10; ++k) provisional[static_cast<std::size_t>(k)][0] = -2.0 + 0.4 * k;
    const tools::ReferenceStream ref = tools::makeSyntheticReference(arm, m, 55, 0, provisional);
    tools::KMeansOptions options;
    centroids.push_back(tools::kmeansPlusPlus(ref.retargeted, options).centroids);
  }
  return centroids;
}

template <class Dims>
void checkHead(const PolicyArch& arch, const std::vector<std::vector<JointVector>>& centroids,
               const std::vector<Sequence>& random, const std::vector<Sequence>& recorded, const std::string& name,
               std::uint64_t seed) {
  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    const tools::PolicyNet net = test::perturbedNet(arch, c, centroids, seed);
    const std::vector<std::vector<float>> floats = tools::manifestFloats(net);
    const std::vector<const float*> p = pointers(floats);
    const PolicyWeights<Dims> weights = bindPolicyWeights<Dims>(p.data(), p.size(), arch, c);
    // The law is the model's tensor: 1.0894 in reference mode, 0 in autonomous mode.
    CHECK(weights.law_gain(2) == (c == Conditioning::kReference ? 1.0894f : 0.0f));
    const std::string mode = conditioningName(c);
    checkParity(net, weights, random, name + "/" + mode + "/random");
    if (!recorded.empty()) checkParity(net, weights, recorded, name + "/" + mode + "/recorded");
  }
}

PolicyArch withChunk(PolicyArch a, int chunk) {
  a.chunk = chunk;
  return a;
}

}  // namespace

TEST_CASE("small configuration, regression of one action: streaming runtime inference equals libtorch's act within 1e-5 (random and recorded rollouts, both modes)") {
  torch::set_num_threads(1);
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const std::vector<std::vector<JointVector>> centroids = syntheticKeyPoses(arm);
  // Longer than W (8) several times over: the ring wraps; steps run past nothing (T < max_steps).
  const std::vector<Sequence> recorded = recordedSequences(arm, centroids, 6, 200);
  const std::vector<Sequence> random = randomSequences(arm, 3, 6, 3 * smallArch().window + 5, 12);
  checkHead<SmallPolicyDims>(smallArch(), centroids, random, recorded, "small C1", 21);
}

TEST_CASE("small configuration, a regressed chunk of 5 with the temporal ensemble (decay 0.3): the runtime equals libtorch's act within 1e-5") {
  torch::set_num_threads(1);
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const std::vector<std::vector<JointVector>> centroids = syntheticKeyPoses(arm);
  const std::vector<Sequence> recorded = recordedSequences(arm, centroids, 3, 120);
  const std::vector<Sequence> random = randomSequences(arm, 3, 6, 3 * smallArch().window + 5, 13);
  checkHead<SmallPolicyDims>(withChunk(smallArch(), 5), centroids, random, recorded, "small C5", 22);
}

TEST_CASE("paper configuration: the runtime equals libtorch's act within 1e-5, a chunk of 1") {
  torch::set_num_threads(1);
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const std::vector<std::vector<JointVector>> centroids = syntheticKeyPoses(arm);
  // 60 ticks = 3 windows (the whole-sequence record needs (T·J)² · d floats: kept short).
  const std::vector<Sequence> random = randomSequences(arm, 3, 3, 60, 15);
  const std::vector<Sequence> recorded = recordedSequences(arm, centroids, 3, 60);
  checkHead<PaperPolicyDims>(paperArch(), centroids, random, recorded, "paper C1", 24);
}

TEST_CASE("small configuration, autonomous with a run code: the runtime's run_code is libtorch's z, within 1e-5") {
  torch::set_num_threads(1);
  torch::NoGradGuard no_grad;
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const std::vector<std::vector<JointVector>> centroids = syntheticKeyPoses(arm);
  const PolicyArch arch = withChunk(smallArch(), 5);
  const tools::PolicyNet net = test::perturbedNet(arch, Conditioning::kAutonomous, centroids, 31);
  const std::vector<std::vector<float>> floats = tools::manifestFloats(net);
  const std::vector<const float*> p = pointers(floats);
  const PolicyWeights<SmallPolicyDims> weights = bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), arch, Conditioning::kAutonomous);
  auto ws = makePolicyWorkspace<SmallPolicyDims>();
  const std::vector<Sequence> seqs = randomSequences(arm, 3, 4, 3 * arch.window + 5, 14);
  double worst = 0.0, moved = 0.0;
  long ticks = 0;
  for (const Sequence& seq : seqs) {
    const torch::Tensor z = torch::randn({1, arch.d_model}) * 0.5;
    tools::PolicyBatch b = normalised(net, seq);
    const auto chunkOf = [&](const tools::PolicyBatch& batch) {
      return (net->forward(batch).chunk * net->a_std.view({1, 1, -1, 1}) + net->a_mean.view({1, 1, -1, 1}))
          .contiguous();
    };
    const torch::Tensor plain = chunkOf(b);
    b.z = z;
    const torch::Tensor coded = chunkOf(b);
    auto tc = coded.accessor<float, 4>();
    auto tp = plain.accessor<float, 4>();
    resetPolicyStream(*ws);
    setPolicyRunCode(*ws, z.contiguous().data_ptr<float>());
    for (std::size_t n = 0; n < seq.size(); ++n, ++ticks) {
      stepPolicy(weights, *ws, seq[n]);
      const long t = static_cast<long>(n);
      for (int j = 0; j < kNumJoints; ++j)
        for (int c = 0; c < arch.chunk; ++c) {
          worst = std::max(worst, std::abs(static_cast<double>(ws->chunk(j, c)) - tc[0][t][j][c]));
          moved = std::max(moved, std::abs(static_cast<double>(tc[0][t][j][c]) - tp[0][t][j][c]));
        }
    }
  }
  MESSAGE("run code: " << ticks << " ticks; worst |chunk difference| " << worst << " rad; the code moves the chunk by up to "
                       << moved << " rad");
  CHECK(worst <= kTolerance);
  CHECK(moved > 1e-3);  // not vacuous: the code changes what the net does
  setPolicyRunCode(*ws, nullptr);
  CHECK(ws->run_code.isZero(0.0f));
}
