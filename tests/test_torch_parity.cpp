// Parity: the runtime's fixed-size float inference (nao/policy.hpp) and libtorch's forward of the
// training module (toolchain/src/torch/) on the same weights agree within 1e-5 absolute on the
// actions and on every cross-attention weight, over 1,000 random and 1,000 recorded inputs, for
// the small configuration (fresh weights, perturbed away from their initialisation) and the
// paper configuration (the committed models/default.bin).
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/reference_source.hpp"
#include "policy_torch.hpp"
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
constexpr int kInputs = 1000;

struct Inputs {
  std::vector<PolicyInput> list;
};

float uniform(std::mt19937_64& rng, double lo, double hi) {
  return static_cast<float>(lo + (hi - lo) * static_cast<double>(rng() >> 11) * 0x1.0p-53);
}

// Random inputs over the arm's range: q inside the limits, a(t-1) up to 0.2 rad, r anywhere in
// the limits, every movement, steps across the embedding (and past it: clamped).
Inputs randomInputs(const ArmModel& arm, int movements, int max_steps, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Inputs in;
  for (int n = 0; n < kInputs; ++n) {
    PolicyInput x;
    for (int j = 0; j < kNumJoints; ++j) {
      x.q[j] = uniform(rng, arm.q_min[j], arm.q_max[j]);
      x.a_prev[j] = uniform(rng, -0.2, 0.2);
      x.r[j] = uniform(rng, arm.q_min[j], arm.q_max[j]);
    }
    x.movement = n % movements;
    x.step = static_cast<int>(rng() % static_cast<std::uint64_t>(max_steps + 20));
    in.list.push_back(x);
  }
  return in;
}

// Recorded inputs: the states a policy sees on held-out synthetic demonstrations (triangulated,
// retargeted, feature-extracted with `centroids`), built as the training samples are.
Inputs recordedInputs(const ArmModel& arm, const std::vector<std::vector<JointVector>>& centroids) {
  Inputs in;
  const tools::Movement movements[3] = {tools::Movement::kElbow, tools::Movement::kWholeArm, tools::Movement::kWrist};
  for (int index = 0; static_cast<int>(in.list.size()) < kInputs; ++index) {
    const int m = index % 3;  // model movement index: elbow 0, whole_arm 1, wrist 2
    const tools::ReferenceStream ref =
        tools::makeSyntheticReference(arm, movements[m], 77, index, centroids[static_cast<std::size_t>(m)]);
    int label = tools::nearestCentroid(centroids[static_cast<std::size_t>(m)], ref.retargeted.front());
    for (std::size_t t = 0; t + 1 < ref.target.size() && static_cast<int>(in.list.size()) < kInputs; ++t) {
      if (ref.measured[t]) label = tools::nearestCentroid(centroids[static_cast<std::size_t>(m)], ref.retargeted[t]);
      PolicyInput x;
      x.q = ref.target[t].cast<float>();
      x.a_prev = (t == 0 ? JointVector::Zero() : JointVector(ref.target[t] - ref.target[t - 1])).cast<float>();
      x.r = centroids[static_cast<std::size_t>(m)][static_cast<std::size_t>(label)].cast<float>();
      x.movement = m;
      x.step = static_cast<int>(t);
      in.list.push_back(x);
    }
  }
  return in;
}

torch::Tensor stack(const Inputs& in, int what) {
  torch::Tensor t = torch::empty({static_cast<long>(in.list.size()), kNumJoints}, torch::kFloat);
  auto a = t.accessor<float, 2>();
  for (std::size_t n = 0; n < in.list.size(); ++n)
    for (int j = 0; j < kNumJoints; ++j) {
      const PolicyInput& x = in.list[n];
      a[static_cast<long>(n)][j] = what == 0 ? x.q[j] : what == 1 ? x.a_prev[j] : x.r[j];
    }
  return t;
}

torch::Tensor indices(const Inputs& in, bool step, int max_steps) {
  torch::Tensor t = torch::empty({static_cast<long>(in.list.size())}, torch::kLong);
  auto a = t.accessor<long, 1>();
  for (std::size_t n = 0; n < in.list.size(); ++n)
    a[static_cast<long>(n)] = step ? std::min(in.list[n].step, max_steps - 1) : in.list[n].movement;
  return t;
}

template <class Dims>
void checkParity(const tools::PolicyNet& net, const PolicyWeights<Dims>& weights, const Inputs& in,
                 const std::string& what) {
  torch::NoGradGuard no_grad;
  tools::PolicyAttention att;
  const torch::Tensor actions = net->act(stack(in, 0), stack(in, 1), stack(in, 2), indices(in, false, Dims::kMaxSteps),
                                         indices(in, true, Dims::kMaxSteps), &att)
                                    .contiguous();
  auto ta = actions.accessor<float, 2>();
  std::vector<torch::Tensor> cross;
  for (const torch::Tensor& c : att.cross) cross.push_back(c.contiguous());
  auto ws = makePolicyWorkspace<Dims>();
  double worst_action = 0.0, worst_alpha = 0.0, worst_score_rel = 0.0, largest_action = 0.0;
  for (std::size_t n = 0; n < in.list.size(); ++n) {
    const auto& a = stepPolicy(weights, *ws, in.list[n]);
    for (int j = 0; j < kNumJoints; ++j) {
      worst_action = std::max(worst_action, std::abs(static_cast<double>(a[j]) - ta[static_cast<long>(n)][j]));
      largest_action = std::max(largest_action, std::abs(static_cast<double>(a[j])));
      const double s_torch = att.score[static_cast<long>(n)][j].item<float>();
      worst_score_rel = std::max(worst_score_rel, std::abs(ws->score[j] - s_torch) / std::max(1.0, std::abs(s_torch)));
    }
    for (int l = 0; l < Dims::kDecoderLayers; ++l) {
      auto c = cross[static_cast<std::size_t>(l)].accessor<float, 4>();
      for (int h = 0; h < Dims::kHeads; ++h)
        for (int i = 0; i < kNumJoints; ++i)
          for (int j = 0; j < kNumJoints; ++j)
            worst_alpha = std::max(worst_alpha, std::abs(static_cast<double>(ws->cross[l][h][i][j]) -
                                                         c[static_cast<long>(n)][h][i][j]));
    }
  }
  MESSAGE(what << ": worst |action difference| " << worst_action << " rad (largest action " << largest_action
               << " rad), worst |alpha difference| " << worst_alpha << ", worst relative score difference "
               << worst_score_rel);
  CHECK(worst_action <= kTolerance);
  CHECK(worst_alpha <= kTolerance);
  CHECK(worst_score_rel <= kTolerance);
  // The comparison is not vacuous: the actions vary.
  CHECK(largest_action > 1e-3);
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

std::vector<const float*> pointers(const std::vector<std::vector<float>>& floats) {
  std::vector<const float*> p;
  for (const auto& f : floats) p.push_back(f.data());
  return p;
}

}  // namespace

TEST_CASE("small configuration: runtime inference equals libtorch within 1e-5 (random and recorded inputs, both modes)") {
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
  const Inputs recorded = recordedInputs(arm, centroids);
  const Inputs random = randomInputs(arm, 3, smallArch().max_steps, 12);

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
    const PolicyWeights<SmallPolicyDims> weights = bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), c);
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
    const PolicyWeights<PaperPolicyDims> weights =
        bindPolicyWeights<PaperPolicyDims>(p.data(), p.size(), model.header.conditioning);
    std::vector<std::vector<JointVector>> centroids(3);
    for (int m = 0; m < 3; ++m)
      for (int k = 0; k < PaperPolicyDims::kClusters; ++k)
        centroids[static_cast<std::size_t>(m)].push_back(centroid(weights, m, k).cast<double>());
    checkParity(net, weights, randomInputs(arm, 3, paperArch().max_steps, 13), std::string(name) + "/random");
    checkParity(net, weights, recordedInputs(arm, centroids), std::string(name) + "/recorded");
    ++checked;
  }
  CHECK(checked == 2);
}
