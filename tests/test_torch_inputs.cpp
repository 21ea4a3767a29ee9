// What the net is allowed to read, in training: the previous action and a per-run latent; and
// the moving average of the weights that training may keep instead. Each is a training-time choice: model.bin's tensors and nao_rt
// stay unchanged (a run latent adds its run codes to the metadata).
#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"
#include "nao/policy.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "run_latent.hpp"
#include "support/small_policy_data.hpp"
#include "train_data.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

using namespace nao;
using namespace nao::tools;

namespace {

using nao::test::smallData;
using nao::test::smallOptions;
using nao::test::resumedBytes;
using nao::test::smallSim;
using nao::test::trainBytes;

}  // namespace

TEST_CASE("without the previous action the net's a(t-1) weights stay zero through training, and the runtime's action ignores a(t-1)") {
  // The same training with and without the input: only the latter must be blind to a(t-1).
  for (const bool previous_action : {true, false}) {
    CAPTURE(previous_action);
    TrainOptions o = smallOptions(81, 2);
    o.conditioning = Conditioning::kAutonomous;
    o.arch.chunk = 3;
    o.previous_action = previous_action;
    TrainResult r;
    const std::vector<std::uint8_t> bytes = trainBytes(o, &r);
    const ModelFile file = decodeModel(bytes, "trained.bin");
    const int d = file.header.arch.d_model;
    // embed.in.weight [features, d] row-major is column-major [d, features]: column 1 is a(t-1)'s.
    const Eigen::Map<const Eigen::MatrixXf> in_w(file.data(file.find("embed.in.weight")), d, file.header.arch.features);
    const Eigen::Map<const Eigen::VectorXf> act_w(file.data(file.find("embed.act.weight")), d);
    CHECK(in_w.col(0).cwiseAbs().sum() > 0.0f);
    CHECK((in_w.col(1).cwiseAbs().sum() == 0.0f) == !previous_action);
    CHECK((act_w.cwiseAbs().sum() == 0.0f) == !previous_action);
    CHECK(nlohmann::json::parse(file.header.metadata_json)["training"].value("previous_action_input", true) ==
          previous_action);

    // Two streams of the runtime on the same joint angles, one fed the previous actions and the
    // other zeros: bit-equal actions exactly when the net does not see them.
    std::vector<const float*> p;
    for (std::size_t i = 0; i < file.tensors.size(); ++i) p.push_back(file.data(i));
    const PolicyWeights<SmallPolicyDims> w =
        bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), file.header.arch, file.header.conditioning);
    ExecutionOptions clean;
    clean.noisy_rollouts = 0;
    const PolicySequence seq = executeDemos(smallData(), {r.split.val.front()}, smallSim(), clean, o.seed).front();
    auto fed = makePolicyWorkspace<SmallPolicyDims>(), blind = makePolicyWorkspace<SmallPolicyDims>();
    resetPolicyStream(*fed);
    resetPolicyStream(*blind);
    bool all_equal = true;
    double largest = 0.0;
    for (std::size_t t = 0; t < seq.ticks(); ++t) {
      PolicyInput in;
      in.q = seq.q[t].cast<float>();
      in.a_prev = seq.a_prev[t].cast<float>();
      in.movement = seq.movement;
      in.step = static_cast<int>(t);
      const Eigen::Matrix<float, 5, 1> a = stepPolicy(w, *fed, in);
      in.a_prev.setZero();
      const Eigen::Matrix<float, 5, 1> b = stepPolicy(w, *blind, in);
      all_equal = all_equal && a == b;
      largest = std::max(largest, static_cast<double>(a.cwiseAbs().maxCoeff()));
    }
    CHECK(all_equal == !previous_action);
    CHECK(largest > 1e-3);
  }
}

TEST_CASE("the run latent reads the run at every stride-th tick up to its last; at ε = 0 it is the projected mean") {
  torch::manual_seed(5);
  RunLatent latent(4, 16);
  constexpr std::int64_t kLong = 250, kShort = 30;
  Padded p;
  p.in.qn = torch::randn({2, kLong, kNumJoints}).requires_grad_(true);
  p.mask = torch::zeros({2, kLong});
  p.mask[0].fill_(1.0);
  p.mask[1].slice(0, 0, kShort).fill_(1.0);
  const RunLatentImpl::Draw draw = latent->forward(p, torch::randn({2, 4}));
  REQUIRE(draw.z_embedded.sizes() == torch::IntArrayRef({2, 16}));
  REQUIRE(draw.kl.sizes() == torch::IntArrayRef({2}));
  CHECK(draw.kl.min().item<float>() > 0.0f);
  (draw.z_embedded.sum() + draw.kl.sum()).backward();
  // The ticks that reach z: the run's ticks k·stride for k < samples, held at its last tick.
  const torch::Tensor reached = p.in.qn.grad().abs().sum(2) > 0;  // [2, T]
  for (std::int64_t b = 0; b < 2; ++b) {
    const std::int64_t len = b == 0 ? kLong : kShort;
    std::set<std::int64_t> expected;
    for (std::int64_t k = 0; k < RunLatentImpl::kSamples; ++k)
      expected.insert(std::min(k * RunLatentImpl::kStride, len - 1));
    for (std::int64_t t = 0; t < kLong; ++t) {
      CAPTURE(b);
      CAPTURE(t);
      CHECK(reached[b][t].item<bool>() == (expected.count(t) == 1));
    }
  }
  SUBCASE("at the prior (μ 0, σ 1) the KL is zero and z is the projected ε") {
    torch::NoGradGuard no_grad;
    latent->moments->weight.zero_();
    latent->moments->bias.zero_();
    const torch::Tensor eps = torch::randn({2, 4});
    const RunLatentImpl::Draw a = latent->forward(p, eps);
    CHECK(a.kl.abs().max().item<float>() == 0.0f);
    // z = ε, projected without a bias: z = 0 (a model without run codes) adds nothing to the tokens.
    CHECK(torch::allclose(a.z_embedded, eps.matmul(latent->project->weight.t()), 1e-6, 1e-7));
    CHECK(latent->forward(p, torch::zeros({2, 4})).z_embedded.abs().max().item<float>() == 0.0f);
  }
}

TEST_CASE("training with a run latent: deterministic, another result, the same model.bin tensors, the run codes in its metadata") {
  TrainOptions o = smallOptions(85, 2);
  o.conditioning = Conditioning::kAutonomous;
  const std::vector<std::uint8_t> none = trainBytes(o);
  o.latent_dims = 4;
  TrainResult r;
  const std::vector<std::uint8_t> a = trainBytes(o, &r), b = trainBytes(o);
  CHECK_MESSAGE(a == b, "two runs with the same seed and latent gave different bytes");
  CHECK_MESSAGE(a != none, "the latent changed nothing in training");
  const ModelFile with = decodeModel(a, "latent.bin"), without = decodeModel(none, "none.bin");
  REQUIRE(with.tensors.size() == without.tensors.size());
  for (std::size_t i = 0; i < with.tensors.size(); ++i) CHECK(with.tensors[i].spec.name == without.tensors[i].spec.name);
  const nlohmann::json meta = nlohmann::json::parse(with.header.metadata_json)["training"];
  CHECK(meta["run_latent"]["dims"] == 4);
  CHECK(r.history.back().train_loss < r.history.front().train_loss);
  // The codes a run chooses from travel in the metadata: one per training demonstration, with
  // its start and the kept weights' P μ of its clean rollout, bit for bit.
  const PolicyData& data = smallData();
  const std::vector<ModelRunCodes> codes = readModelSpec(with.header, RetargetParams{}, "latent.bin").run_codes;
  REQUIRE(codes.size() == static_cast<std::size_t>(data.movements()));
  REQUIRE(r.run_codes.size() == codes.size());
  std::size_t n = 0;
  for (std::size_t m = 0; m < codes.size(); ++m) {
    const ModelRunCodes& c = codes[m];
    n += c.size();
    CHECK(c.code == r.run_codes[m].code);
    float spread = 0.0f;
    for (std::size_t i = 0; i < c.size(); ++i) {
      const auto demo = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& d) { return d.name == c.names[i]; });
      REQUIRE(demo != data.demos.end());
      CHECK(demo->movement == static_cast<int>(m));
      CHECK(c.q[i] == demo->start);
      for (int k = 0; k < c.d; ++k)
        spread = std::max(spread, std::abs(c.code[i * static_cast<std::size_t>(c.d) + static_cast<std::size_t>(k)] - c.code[static_cast<std::size_t>(k)]));
    }
    CHECK(spread > 1e-4f);  // the encoder tells the demonstrations apart
  }
  CHECK(n == r.split.train.size());
  CHECK(modelCard(data, o, r, "cmd", "m.bin").find("| run latent | K 4, KL weight 0.01; " + std::to_string(n) + " run codes") !=
        std::string::npos);
  CHECK(readModelSpec(without.header, RetargetParams{}, "none.bin").run_codes.empty());
}

TEST_CASE("the moving average of the weights: after one step min(D, 0.1) of the start plus the rest of the trained weights; training goes on from the trained weights; what is scored is the average; resumable") {
  // One optimiser step per epoch. The start's weights are those after a step of lr 1e-12 (Adam
  // moves no weight by more than about the learning rate).
  const std::string dir = (std::filesystem::temp_directory_path() / "nao_rt_tests").string();
  const std::string cache = dir + "/ema_execution_" + std::to_string(::getpid());
  std::filesystem::create_directories(cache);
  TrainOptions o = smallOptions(87, 1);
  o.conditioning = Conditioning::kAutonomous;
  o.max_batches = 1;
  o.execution_cache = cache;  // the trainings below execute the demonstrations once
  TrainOptions still = o;
  still.lr = 1e-12;
  const ModelFile start = decodeModel(trainBytes(still), "start.bin");
  const ModelFile stepped = decodeModel(trainBytes(o), "stepped.bin");
  // D 0.5: the first step's decay is the warm-up's 1/10; D 0.05: the decay itself.
  for (const double decay : {0.5, 0.05}) {
    CAPTURE(decay);
    const double d = std::min(decay, 0.1);
    TrainOptions averaged = o;
    averaged.ema_decay = decay;
    const ModelFile average = decodeModel(trainBytes(averaged), "average.bin");
    REQUIRE(average.tensors.size() == stepped.tensors.size());
    double worst = 0.0, moved = 0.0;
    for (std::size_t i = 0; i < average.tensors.size(); ++i) {
      for (std::size_t k = 0; k < average.tensors[i].spec.count(); ++k) {
        const double s0 = start.data(i)[k], s1 = stepped.data(i)[k];
        worst = std::max(worst, std::abs(average.data(i)[k] - (d * s0 + (1.0 - d) * s1)) / (1.0 + std::abs(s1)));
        moved = std::max(moved, std::abs(s1 - s0));
      }
    }
    CHECK(moved > 1e-4);  // the step changed the weights, so the blend is not trivially met
    CHECK(worst <= 1e-6);
    CHECK(nlohmann::json::parse(average.header.metadata_json)["training"].value("ema_decay", 0.0) == decay);
  }

  // Two epochs: the optimiser trains the same weights with and without the average (it is only
  // scored and kept), so the training losses are equal bit for bit.
  TrainOptions full = o;
  full.max_epochs = full.patience = 2;
  TrainResult plain, averaged;
  trainBytes(full, &plain);
  full.ema_decay = 0.5;
  const std::vector<std::uint8_t> uninterrupted = trainBytes(full, &averaged);
  REQUIRE(plain.history.size() == 2);
  REQUIRE(averaged.history.size() == 2);
  for (std::size_t e = 0; e < 2; ++e) CHECK(averaged.history[e].train_loss == plain.history[e].train_loss);
  // What is scored is the average: its validation loss is not the trained weights'.
  CHECK(averaged.history[1].val_loss != plain.history[1].val_loss);
  // One epoch and a resume from its checkpoint: the second epoch's average scores the same bits
  // (so the checkpoint carries the trained weights, the average and its step count), the same
  // epoch is kept and the same bytes are written.
  const std::string ck = dir + "/ema_checkpoint_" + std::to_string(::getpid()) + ".pt";
  TrainResult resumed;
  const std::vector<std::uint8_t> bytes = resumedBytes(full, ck, &resumed);
  CHECK(resumed.resumed_after == 1);
  REQUIRE(resumed.history.size() == 2);
  CHECK(resumed.history[1].val_loss == averaged.history[1].val_loss);
  CHECK(resumed.history[1].train_loss == averaged.history[1].train_loss);
  CHECK(resumed.best_epoch == averaged.best_epoch);
  CHECK_MESSAGE(bytes == uninterrupted, "resumed after epoch 1 of 2, the bytes differ");
  std::filesystem::remove_all(cache);
}

TEST_CASE("the inputs' options are refused where they mean nothing: reference mode, negative sizes, a decay of 1") {
  TrainOptions o = smallOptions(89, 1);
  o.conditioning = Conditioning::kReference;
  TrainOptions latent = o;
  latent.latent_dims = 8;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), latent, nullptr), doctest::Contains("autonomous"), UserError);
  o.conditioning = Conditioning::kAutonomous;
  TrainOptions negative = o;
  negative.latent_dims = -1;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), negative, nullptr), doctest::Contains("negative"), UserError);
  TrainOptions decay = o;
  decay.ema_decay = 1.0;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), decay, nullptr), doctest::Contains("[0, 1)"), UserError);
}

TEST_CASE("the execution cache is keyed by the data's content: the same data reads it, one changed sample executes again") {
  const std::string cache =
      (std::filesystem::temp_directory_path() / "nao_rt_tests" / ("keyed_execution_" + std::to_string(::getpid()))).string();
  std::filesystem::remove_all(cache);
  const auto entries = [&] {
    std::size_t n = 0;
    for (const auto& e : std::filesystem::directory_iterator(cache)) n += e.is_regular_file() ? 1 : 0;
    return n;
  };
  TrainOptions o = smallOptions(91, 1);
  o.max_batches = 1;
  o.execution_cache = cache;
  const TrainResult first = trainPolicy(smallData(), smallSim(), o, nullptr);
  REQUIRE(entries() == 2);  // <key>.train and <key>.val
  const TrainResult again = trainPolicy(smallData(), smallSim(), o, nullptr);
  CHECK(entries() == 2);
  CHECK(again.history.back().train_loss == first.history.back().train_loss);

  // The same demonstrations and names, one sample of one feature trajectory moved by one ulp:
  // a different data set, so a new key and a new execution, never the cached sequences.
  PolicyData changed = smallData();
  double& sample = changed.demos[5].f[20][2];
  sample = std::nextafter(sample, 1.0);
  const TrainResult redone = trainPolicy(changed, smallSim(), o, nullptr);
  CHECK(redone.fingerprint != first.fingerprint);
  CHECK(entries() == 4);
  std::filesystem::remove_all(cache);
}
