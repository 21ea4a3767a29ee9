// Training the policy with libtorch: the module is the manifest, training is deterministic for a
// seed, the exported file reads back to the module's tensors, the loss goes down, early
// stopping exports the best epoch, the attention record follows docs/policy.md; the head's
// training data (chunk targets), models with a chunk that the runtime runs, the autonomous
// starts, and model selection on rollouts through the runtime's own step.
#include "nao/controller.hpp"
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "support/model_spec.hpp"
#include "support/small_policy_data.hpp"
#include "support/test_util.hpp"
#include "train_checkpoint.hpp"
#include "train_data.hpp"
#include "train_select.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <set>

using namespace nao;
using namespace nao::tools;

namespace {

using nao::test::resumedBytes;
using nao::test::smallData;
using nao::test::smallOptions;
using nao::test::smallSim;
using nao::test::trainBytes;

PolicyArch withChunk(PolicyArch a, int chunk) {
  a.chunk = chunk;
  return a;
}

std::vector<TrainedJoint> urdfJoints() { return trainedJoints(loadArmModel(nao::test::kUrdfPath)); }

// `nao_toolchain train` as the toolchain registers it, in an app of its own.
CLI::App* trainCommand(CLI::App& app) {
  for (const CommandEntry& e : commandRegistry())
    if (std::string(e.name) == "train") e.setup(app);
  return app.get_subcommand("train");
}

// smallData() on disk as `nao_toolchain cluster` leaves a data set: centroids.json and
// <demo>/features.csv (every sample measured), all numbers to the last bit.
std::string writeSmallData(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "nao_rt_tests" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const PolicyData& data = smallData();
  nlohmann::json centroids;
  for (std::size_t m = 0; m < data.movement_names.size(); ++m)
    for (const JointVector& c : data.centroids[m])
      centroids["movements"][data.movement_names[m]]["centroids"].push_back(std::vector<double>(c.data(), c.data() + kNumJoints));
  std::ofstream(dir / "centroids.json") << centroids.dump(2) << '\n';
  for (const PolicyDemo& d : data.demos) {
    std::filesystem::create_directories(dir / d.name);
    std::ofstream csv(dir / d.name / "features.csv");
    csv << "t_s,label,measured,f_0,f_1,f_2,f_3,f_4\n";
    char buf[40];
    for (std::size_t t = 0; t < d.f.size(); ++t) {
      std::snprintf(buf, sizeof buf, "%.17g", d.t_s[t]);
      csv << buf << ',' << d.label[t] << ",1";
      for (int j = 0; j < kNumJoints; ++j) {
        std::snprintf(buf, sizeof buf, "%.17g", d.f[t][j]);
        csv << ',' << buf;
      }
      csv << '\n';
    }
  }
  return dir.string();
}

}  // namespace

TEST_CASE("the torch module's tensors are the manifest: same names, shapes and order, nothing else") {
  for (const PolicyArch& arch : {smallArch(), paperArch(), withChunk(smallArch(), 5)})
    for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
      CAPTURE(arch.chunk);
      torch::manual_seed(1);
      const PolicyNet net(arch, c);
      const std::vector<TensorSpec> manifest = policyManifest(arch);
      const auto tensors = manifestTensors(net);
      REQUIRE(tensors.size() == manifest.size());
      std::set<std::string> module_names;
      for (const auto& p : net->named_parameters()) module_names.insert(p.key());
      for (const auto& b : net->named_buffers()) module_names.insert(b.key());
      CHECK(module_names.size() == manifest.size());
      for (std::size_t i = 0; i < manifest.size(); ++i) {
        CHECK(tensors[i].first == manifest[i].name);
        CHECK(module_names.count(manifest[i].name) == 1);
        CHECK(tensors[i].second.sizes().vec() == std::vector<std::int64_t>(manifest[i].shape.begin(), manifest[i].shape.end()));
        CHECK((tensors[i].second.scalar_type() == torch::kFloat));
      }
      // Buffers are exactly the non-trained manifest tensors.
      std::set<std::string> buffers;
      for (const auto& b : net->named_buffers()) buffers.insert(b.key());
      std::set<std::string> expected{"norm.q_mean", "norm.q_std", "norm.a_mean", "norm.a_std", "norm.r_mean",
                                     "norm.r_std",  "centroids",  "law.gain"};
      if (arch.chunk > 1) expected.insert("head.ensemble_decay");
      CHECK(buffers == expected);
      // A fresh net has no law: the trainer sets it (reference mode) or leaves it 0.
      CHECK(net->law_gain.abs().max().item<float>() == 0.0f);
      const torch::Tensor step = net->step_emb;
      if (c == Conditioning::kReference) {
        CHECK_FALSE(step.requires_grad());
        CHECK(step.abs().max().item<float>() == 0.0f);
      } else {
        CHECK(step.requires_grad());
        CHECK(step.abs().max().item<float>() > 0.0f);
      }
      std::size_t count = 0;
      for (const auto& t : tensors) count += static_cast<std::size_t>(t.second.numel());
      CHECK(count == parameterCount(arch));
    }
}

TEST_CASE("the attention record follows docs/policy.md: per-body-part rows sum to 1, mass and age profile are distributions, causal self-attention") {
  torch::manual_seed(3);
  const PolicyArch arch = smallArch();
  const PolicyNet net(arch, Conditioning::kReference);
  {
    // Non-trivial biases so that the check sees them.
    torch::NoGradGuard no_grad;
    for (auto& p : net->parameters())
      if (p.dim() == 1 && p.requires_grad()) p.add_(torch::randn_like(p) * 0.1);
  }
  const std::int64_t n_batch = 2, n_ticks = arch.window + 4, n_joints = arch.tokens, d = arch.d_model,
                     n_heads = arch.heads, window = arch.window;
  PolicyBatch in{torch::randn({n_batch, n_ticks, n_joints}), torch::randn({n_batch, n_ticks, n_joints}),
                 torch::randn({n_batch, n_ticks, n_joints}), torch::tensor({0, 2}, torch::kInt64)};
  PolicyAttention att;
  const PolicyHeadOutput out = net->forward(in, &att);
  CHECK(out.chunk.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_joints, 1});
  REQUIRE(att.cross.size() == static_cast<std::size_t>(arch.decoder_layers));
  for (const torch::Tensor& a : att.cross) {
    CHECK(a.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_heads, n_joints, n_joints});
    CHECK((a.sum(-1) - 1).abs().max().item<float>() < 1e-5f);
  }
  CHECK(att.mass.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_joints});
  CHECK((att.mass.sum(-1) - 1).abs().max().item<float>() < 1e-5f);
  CHECK(att.age_profile.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, window});
  CHECK((att.age_profile.sum(-1) - 1).abs().max().item<float>() < 1e-5f);
  // Tick t has t + 1 ticks of history at most: no mass at older ages.
  for (std::int64_t t = 0; t + 1 < window; ++t)
    CHECK(att.age_profile.select(1, t).slice(1, t + 1, window).abs().max().item<float>() == 0.0f);
  CHECK(att.age_profile.select(1, n_ticks - 1).select(1, window - 1).min().item<float>() > 0.0f);
  CHECK(att.score.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_joints});
  CHECK(att.score.min().item<float>() > 0.0f);
  CHECK(att.cross_out.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_joints, d});

  // Causal self-attention: query i gets weight 0 on keys above i, the rest sums to 1.
  torch::NoGradGuard no_grad;
  torch::Tensor self_alpha;
  const torch::Tensor tokens = torch::randn({n_batch, n_joints, d});
  net->dec.front()->self->forward(tokens, tokens, true, &self_alpha);
  CHECK(self_alpha.triu(1).abs().max().item<float>() == 0.0f);
  CHECK((self_alpha.sum(-1) - 1).abs().max().item<float>() < 1e-6f);
  CHECK(self_alpha.tril(-1).abs().max().item<float>() > 0.0f);

  // The window mask: ages 0..W-1 allowed, the future and older ticks blocked.
  const WindowMask m = windowMask(n_ticks, static_cast<int>(n_joints), static_cast<int>(window), WindowLayout::kFull);
  CHECK_FALSE(m.blocked[3 * n_joints + 1][3 * n_joints + 4].item<bool>());  // same tick, any joint
  CHECK(m.blocked[3 * n_joints][4 * n_joints].item<bool>());               // the next tick
  CHECK_FALSE(m.blocked[(window - 1) * n_joints][0].item<bool>());         // age W-1
  CHECK(m.blocked[window * n_joints][0].item<bool>());                     // age W
  CHECK(m.age[(window - 1) * n_joints][0].item<std::int64_t>() == window - 1);
}

TEST_CASE("a later tick never changes an earlier action (causal in time), a whole-sequence forward equals shorter prefixes") {
  torch::manual_seed(5);
  const PolicyArch arch = smallArch();
  const PolicyNet net(arch, Conditioning::kAutonomous);
  torch::NoGradGuard no_grad;
  const std::int64_t n_ticks = 2 * arch.window + 3;
  PolicyBatch in{torch::randn({1, n_ticks, 5}), torch::randn({1, n_ticks, 5}), torch::randn({1, n_ticks, 5}),
                 torch::tensor({1}, torch::kInt64)};
  const torch::Tensor full = net->forward(in).chunk;
  const std::int64_t cut = arch.window + 1;
  PolicyBatch prefix{in.qn.slice(1, 0, cut), in.an.slice(1, 0, cut), in.rn.slice(1, 0, cut), in.movement};
  CHECK((net->forward(prefix).chunk - full.slice(1, 0, cut)).abs().max().item<float>() < 1e-5f);
}

TEST_CASE("the blocked layout of the window attention is the full one: outputs, gradients and the attention record") {
  torch::manual_seed(9);
  const auto maxAbs = [](const torch::Tensor& t) { return t.abs().max().item<double>(); };
  // The small architecture's window, and windows of 1 tick (a block is one tick) and 3.
  for (const int window : {smallArch().window, 1, 3}) {
    CAPTURE(window);
    PolicyArch arch = smallArch();
    arch.window = window;
    PolicyNet net(arch, Conditioning::kAutonomous);
    const std::vector<torch::Tensor> params = net->trainableParameters();
    const std::int64_t w = window;
    const auto isAgeBias = [&](const torch::Tensor& p) { return p.dim() == 2 && p.size(0) == arch.heads && p.size(1) == w; };
    {
      // Non-zero biases and age biases, so that a misplaced age or block shows.
      torch::NoGradGuard no_grad;
      for (auto& p : net->parameters())
        if (p.dim() == 1 || isAgeBias(p)) p.add_(torch::randn_like(p) * 0.3);
    }
    // 1 tick, less than a block, a block, a block and a bit, several with a ragged end.
    for (const std::int64_t n_ticks : {std::int64_t{1}, std::max<std::int64_t>(w - 1, 1), w, w + 1, 2 * w + 3, 5 * w + 2}) {
      CAPTURE(n_ticks);
      PolicyBatch in{torch::randn({2, n_ticks, 5}), torch::randn({2, n_ticks, 5}), torch::randn({2, n_ticks, 5}),
                     torch::tensor({0, 2}, torch::kInt64)};
      const torch::Tensor target = torch::randn({2, n_ticks, 5, 1});
      torch::Tensor out[2];
      std::vector<torch::Tensor> grad[2];
      PolicyAttention att[2];
      const WindowLayout layouts[2] = {WindowLayout::kFull, WindowLayout::kBlocked};
      for (int l = 0; l < 2; ++l) {
        net->window_layout = layouts[l];
        for (const torch::Tensor& p : params) p.mutable_grad() = torch::Tensor();
        out[l] = net->forward(in).chunk;
        (out[l] - target).square().mean().backward();
        for (const torch::Tensor& p : params) grad[l].push_back(p.grad().clone());
        torch::NoGradGuard no_grad;
        net->forward(in, &att[l]);
      }
      net->window_layout = WindowLayout::kAuto;
      CHECK(maxAbs(out[0]) > 0.1);
      CHECK(maxAbs(out[0] - out[1]) < 1e-5);
      // Float sums over other counts of exact zeros: rounding apart, the same gradient. Some are
      // zero but for rounding (a key bias shifts every score of a query alike), so the measure
      // is the whole gradient's norm.
      double diff2 = 0.0, norm2 = 0.0, age_bias_grad = 0.0;
      for (std::size_t i = 0; i < params.size(); ++i) {
        diff2 += (grad[0][i] - grad[1][i]).square().sum().item<double>();
        norm2 += grad[0][i].square().sum().item<double>();
        if (isAgeBias(params[i])) age_bias_grad = std::max(age_bias_grad, maxAbs(grad[0][i]));
      }
      CHECK(std::sqrt(diff2 / norm2) < 1e-6);
      // The age biases learn once a window holds older ticks (with W = 1 there is only age 0,
      // a shift of every score alike).
      if (n_ticks > 1 && w > 1) CHECK(age_bias_grad > 1e-6);
      for (std::size_t k = 0; k < att[0].cross.size(); ++k) CHECK(maxAbs(att[0].cross[k] - att[1].cross[k]) < 1e-6);
      CHECK(maxAbs(att[0].age_profile - att[1].age_profile) < 1e-6);
      CHECK(maxAbs(att[0].score - att[1].score) <= 1e-5 * maxAbs(att[0].score));
    }
  }
  // The automatic choice: the full layout for short sequences, blocks of W from ~2.2 W on.
  const std::int64_t w = smallArch().window;
  CHECK(windowMask(2 * w, 5, static_cast<int>(w)).blocks == 0);
  CHECK(windowMask(3 * w, 5, static_cast<int>(w)).blocks == 3);
  CHECK(windowMask(3 * w + 1, 5, static_cast<int>(w)).blocks == 4);
}

TEST_CASE("reference mode ignores the step, autonomous mode ignores the reference") {
  torch::manual_seed(4);
  const PolicyArch arch = smallArch();
  const PolicyNet ref(arch, Conditioning::kReference), aut(arch, Conditioning::kAutonomous);
  torch::NoGradGuard no_grad;
  PolicyBatch in{torch::randn({2, 6, 5}), torch::randn({2, 6, 5}), torch::randn({2, 6, 5}),
                 torch::tensor({0, 2}, torch::kInt64)};
  PolicyBatch other_ref = in;
  other_ref.rn = torch::randn({2, 6, 5});
  CHECK_FALSE(torch::equal(ref->forward(in).chunk, ref->forward(other_ref).chunk));
  CHECK(torch::equal(aut->forward(in).chunk, aut->forward(other_ref).chunk));
  // The step rows: zero and frozen in reference mode (see the manifest test), used in autonomous.
  CHECK(ref->step_emb.abs().max().item<float>() == 0.0f);
  const torch::Tensor with_steps = aut->forward(in).chunk;
  const torch::Tensor saved = aut->step_emb.clone();
  aut->step_emb.zero_();
  const torch::Tensor without_steps = aut->forward(in).chunk;
  aut->step_emb.copy_(saved);
  CHECK_FALSE(torch::equal(with_steps, without_steps));
}

TEST_CASE("training twice with one seed gives byte-identical model.bin bytes, another seed other bytes") {
  TrainResult first;
  const std::vector<std::uint8_t> a = trainBytes(smallOptions(11, 3), &first);
  const std::vector<std::uint8_t> b = trainBytes(smallOptions(11, 3));
  const std::vector<std::uint8_t> c = trainBytes(smallOptions(12, 3));
  CHECK(a.size() == b.size());
  CHECK_MESSAGE(a == b, "two runs with seed 11 gave different bytes");
  CHECK_MESSAGE(a != c, "seeds 11 and 12 gave the same bytes");

  SUBCASE("the training loss decreases") {
    REQUIRE(first.history.size() == 3);
    CHECK_MESSAGE(first.history.back().train_loss < 0.9 * first.history.front().train_loss,
                  "train loss " << first.history.front().train_loss << " -> " << first.history.back().train_loss);
  }
}

TEST_CASE("the written model.bin reads back: header, metadata and every tensor equal the trained module's") {
  const TrainOptions o = smallOptions(21, 2);
  const TrainResult r = trainPolicy(smallData(), smallSim(), o, nullptr);
  const std::string path = nao::test::writeTempFile("torch_train_model.bin", "");
  writeModelFile(path, modelHeader(smallData(), o, r, urdfJoints()), manifestFloats(r.net));
  const ModelFile file = readModelFile(path);
  checkJointsMatch(file, loadArmModel(nao::test::kUrdfPath), path);
  CHECK(file.header.arch == o.arch);
  CHECK(file.header.conditioning == Conditioning::kReference);
  CHECK(file.header.movement_names == std::vector<std::string>{"elbow", "whole_arm", "wrist"});

  const auto tensors = manifestTensors(r.net);
  REQUIRE(file.tensors.size() == tensors.size());
  for (std::size_t i = 0; i < tensors.size(); ++i) {
    const torch::Tensor t = tensors[i].second.detach().contiguous();
    REQUIRE(file.tensors[i].spec.name == tensors[i].first);
    CHECK_MESSAGE(std::memcmp(file.data(i), t.data_ptr<float>(), static_cast<std::size_t>(t.numel()) * sizeof(float)) == 0,
                  tensors[i].first << " differs from the module's tensor");
  }
  // norm.* and centroids hold the training-split statistics and the data's centroids.
  const float* a_std = file.data(file.find("norm.a_std"));
  for (int j = 0; j < kNumJoints; ++j) CHECK(a_std[j] == static_cast<float>(r.stats.a_std[j]));
  const float* centroids = file.data(file.find("centroids"));
  CHECK(centroids[(1 * 10 + 3) * kNumJoints + 2] == static_cast<float>(smallData().centroids[1][3][2]));

  const nlohmann::json meta = nlohmann::json::parse(file.header.metadata_json);
  CHECK(meta["data"]["fingerprint"] == hex64(dataFingerprint(smallData())));
  CHECK(meta["training"]["seed"] == 21);
  CHECK(meta["result"]["epochs_run"] == 2);
  CHECK(meta["split"]["val"].size() == r.split.val.size());
  CHECK(meta["baselines_rad2"]["val"]["zero_action"].get<double>() == r.val_baselines.zero_action);
  CHECK(meta["baselines_rad2"]["val"]["gain_law"].get<double>() == r.val_baselines.gain_law);
  CHECK(file.header.metadata_json.find("time") == std::string::npos);
  // Reference mode's law: the servo inversion over one tick (1.0894 for the default servo), in
  // the file as law.gain and in the metadata.
  CHECK(r.law_gain == servoStepGain(smallSim().params));
  CHECK(meta["training"]["law_gain"].get<double>() == r.law_gain);
  const float* law = file.data(file.find("law.gain"));
  for (int j = 0; j < kNumJoints; ++j) CHECK(law[j] == static_cast<float>(r.law_gain));
  CHECK(meta["config"]["head"] == "regression");
  CHECK(meta["config"]["chunk"] == 1);
  CHECK(meta["config"]["bins"] == 0);
}

TEST_CASE("train --help lists at most 25 options: the training method's options are recipe-only, refused on the command line, and a recipe's are honoured") {
  const char* recipe_only[] = {"--noisy-rollouts", "--noisy-starts", "--chunk", "--no-previous-action", "--run-latent",
                               "--latent-kl", "--ema", "--closed-loop-epochs", "--closed-loop-lr", "--closed-loop-horizon",
                               "--closed-loop-horizon-growth", "--closed-loop-starts", "--closed-loop-action-weight"};
  const std::string data = writeSmallData("recipe_only_data");
  const std::string out = (std::filesystem::path(data) / "model.bin").string();
  {
    CLI::App app;
    CLI::App* train = trainCommand(app);
    REQUIRE(train != nullptr);
    CHECK(train->get_options().size() <= 25);  // --help included
    const std::string help = train->help();
    CHECK(help.find("docs/training.md") != std::string::npos);
    for (const char* flag : recipe_only) {
      CAPTURE(flag);
      CHECK_THROWS_AS(train->get_option(flag), CLI::OptionNotFound);
    }
  }
  for (const char* flag : recipe_only) {
    CAPTURE(flag);
    CLI::App app;
    trainCommand(app);
    const std::string value = std::string(flag) == "--no-previous-action" ? "" : " 1";
    CHECK_THROWS_AS(app.parse("train --config small --epochs 1 --max-batches 1 --data " + data + " --out " + out + " " +
                                  flag + value,
                              false),
                    CLI::ParseError);
    CHECK_FALSE(std::filesystem::exists(out));
  }

  // A recipe sets them: an integer, a choice, a flag and a number, each in the model's header and metadata.
  const std::string recipe = nao::test::writeTempFile(
      "recipe_only.json",
      R"({"train": {"config": "small", "seed": 3, "lr": 0.001, "epochs": 1, "max-batches": 1, "val-fraction": 0.25,
                    "chunk": 4, "noisy-rollouts": 0, "noisy-starts": "others", "no-previous-action": true, "ema": 0.5}})");
  {
    CLI::App app;
    trainCommand(app);
    app.parse("train --recipe " + recipe + " --data " + data + " --out " + out, false);
  }
  const ModelFile file = readModelFile(out);
  CHECK(file.header.arch.chunk == 4);
  const nlohmann::json meta = nlohmann::json::parse(file.header.metadata_json);
  CHECK(meta["config"]["chunk"] == 4);
  CHECK(meta["training"]["seed"] == 3);
  CHECK(meta["training"]["execution"]["noisy_rollouts"] == 0);
  CHECK(meta["training"]["execution"]["noisy_starts"] == "others");
  CHECK(meta["training"]["previous_action_input"] == false);
  CHECK(meta["training"]["ema_decay"].get<double>() == 0.5);
  std::filesystem::remove_all(data);
}

TEST_CASE("early stopping exports the best epoch's weights") {
  TrainOptions o = smallOptions(31, 4);
  o.lr = 3e-2;  // large enough that validation loss is not monotone
  o.patience = 2;
  const TrainResult r = trainPolicy(smallData(), smallSim(), o, nullptr);
  REQUIRE(r.best_epoch >= 1);
  double best = 1e300;
  for (const EpochStats& e : r.history) best = std::min(best, e.val_loss);
  CHECK(r.history[static_cast<std::size_t>(r.best_epoch - 1)].val_loss == best);
  CHECK(r.val.loss == r.history[static_cast<std::size_t>(r.best_epoch - 1)].val_loss);
  ExecutionOptions clean = o.execution;
  clean.noisy_rollouts = 0;
  CHECK(evaluateLoss(r.net, toTensors(r.net, executeDemos(smallData(), r.split.val, smallSim(), clean, o.seed))).loss ==
        r.val.loss);
  CHECK(static_cast<int>(r.history.size()) <= std::min(o.max_epochs, r.best_epoch + o.patience));
}

namespace {

/// Hand-made sequences: values from a seeded generator, lengths `lengths`.
std::vector<PolicySequence> randomSequences(const std::vector<int>& lengths, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const auto u = [&rng](double lo, double hi) { return lo + (hi - lo) * static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  std::vector<PolicySequence> out;
  for (std::size_t i = 0; i < lengths.size(); ++i) {
    PolicySequence s;
    s.demo = static_cast<int>(i);
    s.movement = static_cast<int>(i % 3);
    for (int t = 0; t < lengths[i]; ++t) {
      JointVector q, a_prev, r, a;
      for (int j = 0; j < kNumJoints; ++j) {
        q[j] = u(-1.0, 1.0);
        a_prev[j] = u(-0.05, 0.05);
        r[j] = u(-0.1, 0.1);
        a[j] = u(-0.08, 0.08);
      }
      s.q.push_back(q);
      s.a_prev.push_back(a_prev);
      s.r.push_back(r);
      s.a.push_back(a);
    }
    out.push_back(s);
  }
  return out;
}

NormStats someStats() {
  NormStats st;
  for (int j = 0; j < kNumJoints; ++j) {
    st.q_mean[j] = 0.1 * j;
    st.q_std[j] = 0.5 + 0.1 * j;
    st.a_mean[j] = 0.002 * (j - 2);
    st.a_std[j] = 0.03 + 0.005 * j;
    st.r_mean[j] = -0.01 * j;
    st.r_std[j] = 0.06;
  }
  return st;
}

}  // namespace

TEST_CASE("toTensors' chunk targets: entry (t, j, c) is (a(t+c) − law·r(t+c) − mean) / std, with a = r = 0 past the end") {
  const std::vector<PolicySequence> seqs = randomSequences({7, 3, 12}, 5);
  const NormStats st = someStats();
  for (Conditioning cond : {Conditioning::kReference, Conditioning::kAutonomous}) {
    CAPTURE(conditioningName(cond));
    torch::manual_seed(1);
    PolicyNet net(withChunk(smallArch(), 4), cond);
    net->setNormalisation(st);
    net->setLawGain(1.25);  // the law an autonomous model never has
    const double law = cond == Conditioning::kReference ? 1.25 : 0.0;
    const SequenceTensors t = toTensors(net, seqs);
    REQUIRE(t.size() == seqs.size());
    CHECK(t.ticks == 7 + 3 + 12);
    double worst = 0.0;
    int past_end = 0;
    for (std::size_t i = 0; i < seqs.size(); ++i) {
      const PolicySequence& s = seqs[i];
      const auto n = static_cast<std::int64_t>(s.ticks());
      REQUIRE(t.target[i].sizes().vec() == std::vector<std::int64_t>{n, kNumJoints, 4});
      CHECK(t.movement[i] == s.movement);
      auto target = t.target[i].accessor<float, 3>();
      auto qn = t.qn[i].accessor<float, 2>();
      auto an = t.an[i].accessor<float, 2>();
      auto rn = t.rn[i].accessor<float, 2>();
      auto action = t.action[i].accessor<float, 2>();
      auto r = t.r[i].accessor<float, 2>();
      for (std::int64_t k = 0; k < n; ++k) {
        const auto tk = static_cast<std::size_t>(k);
        for (int j = 0; j < kNumJoints; ++j) {
          worst = std::max({worst, std::abs(qn[k][j] - (s.q[tk][j] - st.q_mean[j]) / st.q_std[j]),
                            std::abs(an[k][j] - (s.a_prev[tk][j] - st.a_mean[j]) / st.a_std[j]),
                            std::abs(rn[k][j] - (s.r[tk][j] - st.r_mean[j]) / st.r_std[j]),
                            std::abs(action[k][j] - s.a[tk][j]), std::abs(r[k][j] - s.r[tk][j])});
          for (int c = 0; c < 4; ++c) {
            const std::size_t at = tk + static_cast<std::size_t>(c);
            const bool inside = at < s.ticks();
            past_end += inside ? 0 : 1;
            const double a = inside ? s.a[at][j] : 0.0, rr = inside ? s.r[at][j] : 0.0;
            const double expected = (a - law * rr - st.a_mean[j]) / st.a_std[j];
            worst = std::max(worst, std::abs(target[k][j][c] - expected) / std::max(1.0, std::abs(expected)));
          }
        }
      }
    }
    MESSAGE(conditioningName(cond) << ": worst relative difference " << worst << ", " << past_end << " entries past an end");
    CHECK(worst < 1e-5);
    CHECK(past_end == 3 * 5 * (1 + 2 + 3));  // the last 3 ticks of each sequence reach past its end
  }
}

TEST_CASE("a regressed chunk of 5 trains deterministically, loads into the runtime, and stepPolicy runs it as libtorch's act") {
  const int chunk = 5;
  TrainOptions o = smallOptions(61, 1);
  o.arch.chunk = chunk;
  TrainResult r;
  const std::vector<std::uint8_t> bytes = trainBytes(o, &r);
  CHECK_MESSAGE(bytes == trainBytes(o), "two runs with seed 61 gave different bytes");
  const ModelFile file = decodeModel(bytes, "trained.bin");
  CHECK(file.header.arch.chunk == chunk);
  const nlohmann::json meta = nlohmann::json::parse(file.header.metadata_json);
  CHECK(meta["config"]["head"] == "regression");
  CHECK(meta["training"]["ensemble_decay"] == 0.0);
  // The runtime binds the file and steps it: the same actions as libtorch's act on a validation
  // demonstration's executed inputs.
  std::vector<const float*> p;
  for (std::size_t i = 0; i < file.tensors.size(); ++i) p.push_back(file.data(i));
  const PolicyWeights<SmallPolicyDims> w =
      bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), file.header.arch, file.header.conditioning);
  CHECK(w.ensemble_weight[1][1] == doctest::Approx(0.5).epsilon(1e-6));  // equal weights
  ExecutionOptions clean;
  clean.noisy_rollouts = 0;
  const PolicySequence seq = executeDemos(smallData(), {r.split.val.front()}, smallSim(), clean, o.seed).front();
  const auto n = static_cast<std::int64_t>(seq.ticks());
  torch::Tensor q = torch::empty({1, n, kNumJoints}), a_prev = torch::empty({1, n, kNumJoints}),
                rr = torch::empty({1, n, kNumJoints});
  for (std::int64_t t = 0; t < n; ++t)
    for (int j = 0; j < kNumJoints; ++j) {
      q[0][t][j] = static_cast<float>(seq.q[static_cast<std::size_t>(t)][j]);
      a_prev[0][t][j] = static_cast<float>(seq.a_prev[static_cast<std::size_t>(t)][j]);
      rr[0][t][j] = static_cast<float>(seq.r[static_cast<std::size_t>(t)][j]);
    }
  torch::NoGradGuard no_grad;
  const torch::Tensor act =
      r.net->act(q, a_prev, rr, torch::tensor({static_cast<std::int64_t>(seq.movement)})).contiguous();
  auto ws = makePolicyWorkspace<SmallPolicyDims>();
  resetPolicyStream(*ws);
  double worst = 0.0, largest = 0.0;
  for (std::int64_t t = 0; t < n; ++t) {
    PolicyInput in;
    in.q = seq.q[static_cast<std::size_t>(t)].cast<float>();
    in.a_prev = seq.a_prev[static_cast<std::size_t>(t)].cast<float>();
    in.r = seq.r[static_cast<std::size_t>(t)].cast<float>();
    in.movement = seq.movement;
    in.step = static_cast<int>(t);
    const Eigen::Matrix<float, 5, 1>& a = stepPolicy(w, *ws, in);
    for (int j = 0; j < kNumJoints; ++j) {
      worst = std::max(worst, std::abs(static_cast<double>(a[j]) - act[0][t][j].item<float>()));
      largest = std::max(largest, std::abs(static_cast<double>(a[j])));
    }
  }
  MESSAGE("chunk " << chunk << ": |runtime − libtorch| " << worst << " rad over " << n
                   << " ticks, largest action " << largest << " rad");
  CHECK(worst <= 1e-5);
  CHECK(largest > 1e-3);
}

TEST_CASE("the law training uses: reference mode the servo inversion over one tick, autonomous mode none") {
  TrainOptions o = smallOptions(1, 1);
  CHECK(lawGain(o, smallSim()) == servoStepGain(smallSim().params));
  CHECK(lawGain(o, smallSim()) == doctest::Approx(1.0894).epsilon(1e-4));
  o.conditioning = Conditioning::kAutonomous;
  CHECK(lawGain(o, smallSim()) == 0.0);
}

namespace {

// smallData() with every demonstration's start moved off its f(0) (a demonstrator's own first
// pose, not the first key pose's blend).
const PolicyData& startedData() {
  static const PolicyData data = [] {
    PolicyData d = smallData();
    for (std::size_t i = 0; i < d.demos.size(); ++i)
      for (int j = 0; j < kNumJoints; ++j) d.demos[i].start[j] = d.demos[i].f.front()[j] + 0.05 * static_cast<double>((i + static_cast<std::size_t>(j)) % 3) - 0.05;
    return d;
  }();
  return data;
}

}  // namespace

TEST_CASE("an autonomous model's metadata carries the starts of its validation demonstrations: names, lengths and start poses") {
  TrainOptions o = smallOptions(71, 1);
  o.conditioning = Conditioning::kAutonomous;
  const PolicyData& data = startedData();
  const TrainResult r = trainPolicy(data, smallSim(), o, nullptr);
  const std::string meta = modelMetadata(data, o, r);
  const ModelStarts starts = nao::test::specOf(meta, data.movement_names, o.arch.d_model, "trained").starts;
  REQUIRE(starts.size() == 3);
  std::size_t listed = 0;
  for (int m = 0; m < 3; ++m) {
    std::vector<int> val;
    for (int d : r.split.val)
      if (data.demos[static_cast<std::size_t>(d)].movement == m) val.push_back(d);
    REQUIRE(starts[static_cast<std::size_t>(m)].size() == val.size());
    for (std::size_t k = 0; k < val.size(); ++k) {
      const PolicyDemo& demo = data.demos[static_cast<std::size_t>(val[k])];
      const ModelStart& st = starts[static_cast<std::size_t>(m)][k];
      CHECK(st.name == demo.name);
      CHECK(st.ticks == static_cast<std::int64_t>(demo.f.size()));
      CHECK(st.q == demo.start);  // written with all digits: the doubles themselves
      CHECK(st.q != demo.f.front());
      ++listed;
    }
  }
  CHECK(listed == r.split.val.size());
  CHECK(nlohmann::json::parse(meta)["training"]["starts"] == "each demonstration's retargeted first pose");
  // It learnt from its demonstrators' own starts: other starts are other training data.
  const TrainResult from_f0 = trainPolicy(smallData(), smallSim(), o, nullptr);
  CHECK(from_f0.val_baselines.zero_action != r.val_baselines.zero_action);
}

TEST_CASE("netRuns drives the runtime's step from each start: its actions are libtorch's act on the states the run visited") {
  torch::manual_seed(8);
  PolicyNet net(withChunk(smallArch(), 3), Conditioning::kAutonomous);
  {
    torch::NoGradGuard no_grad;
    for (torch::Tensor& p : net->trainableParameters()) p.add_(torch::randn_like(p) * 0.05);
  }
  ExecutionOptions clean;
  clean.noisy_rollouts = 0;
  const PolicyData data = fromOwnStarts(startedData());
  net->setNormalisation(normStats(executeDemos(data, {0, 4, 8}, smallSim(), clean, 1)));
  net->setCentroids(data.centroids);
  net->setEnsembleDecay(0.2);
  net->eval();
  const std::vector<int> demos = {1, 6, 11};
  const std::vector<PolicyRun> runs = netRuns(data, demos, smallSim(), net);
  REQUIRE(runs.size() == demos.size());
  const std::vector<PolicyRun> again = netRuns(data, demos, smallSim(), net);  // deterministic
  for (std::size_t i = 0; i < runs.size(); ++i) {
    CHECK(again[i].q == runs[i].q);
    CHECK(again[i].a == runs[i].a);
  }
  const ArmModel& arm = smallSim().arm;
  const double period = smallSim().params.dt_s * smallSim().params.substeps_per_tick;
  torch::NoGradGuard no_grad;
  double worst = 0.0, largest = 0.0;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const PolicyRun& run = runs[i];
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(demos[i])];
    CHECK(run.demo == demos[i]);
    REQUIRE(run.q.size() == demo.f.size());
    REQUIRE(run.a.size() == demo.f.size() - 1);
    // The data's own start begins f; the run begins there (clamped to the limits, as resetSim).
    CHECK((demo.f.front() - startedData().demos[static_cast<std::size_t>(demos[i])].start).cwiseAbs().maxCoeff() < 1e-12);
    CHECK((run.q.front() - clampToLimits(arm, demo.f.front())).cwiseAbs().maxCoeff() < 1e-9);
    // The inputs the controller gave: q(t), the applied (limited) a(t−1), r = clamped f(t+1) − q.
    const auto n = static_cast<std::int64_t>(run.a.size());
    torch::Tensor q = torch::empty({1, n, kNumJoints}), a_prev = torch::zeros({1, n, kNumJoints}),
                  r = torch::empty({1, n, kNumJoints});
    for (std::int64_t t = 0; t < n; ++t) {
      const auto tk = static_cast<std::size_t>(t);
      const JointVector rr = clampToLimits(arm, demo.f[tk + 1]) - run.q[tk];
      for (int j = 0; j < kNumJoints; ++j) {
        q[0][t][j] = static_cast<float>(run.q[tk][j]);
        r[0][t][j] = static_cast<float>(rr[j]);
      }
      if (t + 1 < n) {
        // The controller's limiter with the autonomous workspace: the demonstrations' joint
        // range widened by the controller's margin.
        JointEnvelope env;
        const ModelWorkspace w = demonstratedWorkspace(data)[static_cast<std::size_t>(run.movement)];
        env.lo = w.lo.array() - ControllerParams{}.workspace_margin_rad;
        env.hi = w.hi.array() + ControllerParams{}.workspace_margin_rad;
        JointVector c;
        limitCommand(arm, period, run.q[tk], run.a[tk], c, &env);
        for (int j = 0; j < kNumJoints; ++j) a_prev[0][t + 1][j] = static_cast<float>(c[j] - run.q[tk][j]);
      }
    }
    const torch::Tensor act = net->act(q, a_prev, r, torch::tensor({static_cast<std::int64_t>(run.movement)})).contiguous();
    for (std::int64_t t = 0; t < n; ++t)
      for (int j = 0; j < kNumJoints; ++j) {
        worst = std::max(worst, std::abs(run.a[static_cast<std::size_t>(t)][j] - act[0][t][j].item<float>()));
        largest = std::max(largest, std::abs(run.a[static_cast<std::size_t>(t)][j]));
      }
  }
  MESSAGE("netRuns vs libtorch's act on the visited states: worst " << worst << " rad, largest action " << largest << " rad");
  CHECK(worst <= 1e-5);
  CHECK(largest > 1e-3);
  // Only the dimensions the runtime is compiled for.
  CHECK(hasRuntimeStep(smallArch()));
  CHECK(hasRuntimeStep(withChunk(paperArch(), kPolicyMaxChunk)));
  CHECK_FALSE(hasRuntimeStep(withChunk(smallArch(), kPolicyMaxChunk + 1)));
  PolicyArch window = smallArch();
  window.window = 9;
  CHECK_FALSE(hasRuntimeStep(window));
  torch::manual_seed(9);
  const PolicyNet other(window, Conditioning::kAutonomous);
  CHECK_THROWS_AS(netRuns(data, demos, smallSim(), other), UserError);
}

TEST_CASE("betterEpoch prefers an epoch that makes the movement, then one that makes more movements, then the lower rollout DTW; a NaN never wins; scoreRuns scores a non-finite run NaN") {
  EpochStats moves, close, far, broken;
  moves.rollout_dtw_m = 0.03;
  moves.makes_movement = true;
  close.rollout_dtw_m = 0.01;
  far.rollout_dtw_m = 0.02;
  broken.rollout_dtw_m = std::numeric_limits<double>::quiet_NaN();
  CHECK(betterEpoch(moves, close));
  CHECK_FALSE(betterEpoch(close, moves));
  CHECK(betterEpoch(close, far));
  CHECK_FALSE(betterEpoch(far, close));
  CHECK(betterEpoch(far, broken));
  CHECK_FALSE(betterEpoch(broken, far));
  CHECK_FALSE(betterEpoch(broken, broken));
  EpochStats two = far, one = close;
  two.movements_made = 2;
  one.movements_made = 1;
  CHECK(betterEpoch(two, one));  // more movements made wins over a lower DTW
  CHECK_FALSE(betterEpoch(one, two));
  CHECK(betterEpoch(moves, two));

  const PolicyData& data = smallData();
  const std::vector<int> val = {1, 5, 9};  // one demonstration of each movement
  const double period = ControllerParams{}.period_s;
  const SelectionReference ref = selectionReference(data, val, smallSim().arm, period);
  REQUIRE(ref.demos.size() == 3);
  // The demonstrations themselves as runs: DTW 0 to the nearest (themselves), speed ratio 1.
  std::vector<PolicyRun> runs;
  for (int d : val) runs.push_back({d, data.demos[static_cast<std::size_t>(d)].movement, data.demos[static_cast<std::size_t>(d)].f, {}});
  EpochStats st;
  scoreRuns(runs, ref, smallSim().arm, period, st);
  REQUIRE(st.rollouts.size() == 3);
  CHECK(st.rollout_dtw_m == 0.0);
  for (const MovementScore& m : st.rollouts) {
    CHECK(m.speed_ratio == doctest::Approx(1.0));
    CHECK(m.loops_run == m.loops_demo);
    CHECK(m.range_excess_rad <= 0.0);
  }
  CHECK(st.makes_movement);
  CHECK(st.movements_made == 3);
  // Runs 1 mrad off their demonstrations keep speed, loops and range; whether the movement is
  // made then rests on the DTW bar: under twice the demonstrations' nearest-neighbour DTW (one
  // validation demonstration each here, so NaN: not asked until set).
  std::vector<PolicyRun> off = runs;
  for (PolicyRun& r : off)
    for (JointVector& q : r.q) q[0] += 1e-3;
  EpochStats near_run;
  scoreRuns(off, ref, smallSim().arm, period, near_run);
  CHECK(std::isnan(ref.nn_dtw_m[0]));
  CHECK(near_run.movements_made == 3);
  const double d0 = near_run.rollouts[0].dtw_m;
  REQUIRE(d0 > 0.0);
  SelectionReference strict = ref;
  strict.nn_dtw_m[0] = 0.25 * d0;  // the run is at 4x the demonstrations' own: not made
  EpochStats far_run;
  scoreRuns(off, strict, smallSim().arm, period, far_run);
  CHECK(far_run.movements_made == 2);
  CHECK_FALSE(far_run.makes_movement);
  CHECK(far_run.rollouts[0].speed_ratio == near_run.rollouts[0].speed_ratio);
  strict.nn_dtw_m[0] = 0.6 * d0;  // at 1.7x: made
  scoreRuns(off, strict, smallSim().arm, period, far_run);
  CHECK(far_run.movements_made == 3);
  runs[1].q[4][2] = std::numeric_limits<double>::quiet_NaN();
  EpochStats nan;
  scoreRuns(runs, ref, smallSim().arm, period, nan);
  CHECK(std::isnan(nan.rollouts[1].dtw_m));
  CHECK(std::isnan(nan.rollout_dtw_m));
  CHECK_FALSE(betterEpoch(nan, far));
}

TEST_CASE("rollout selection exports the best epoch by its autonomous rollouts, records their scores, and stays deterministic") {
  TrainOptions o = smallOptions(43, 3);
  o.conditioning = Conditioning::kAutonomous;
  o.select_by_rollout = true;
  TrainResult r;
  const std::vector<std::uint8_t> a = trainBytes(o, &r);
  REQUIRE(r.history.size() == 3);
  int best = 0;
  for (const EpochStats& e : r.history) {
    REQUIRE(e.rollouts.size() == 3);
    if (best == 0 || betterEpoch(e, r.history[static_cast<std::size_t>(best - 1)])) best = e.epoch;
  }
  CHECK(r.best_epoch == best);
  REQUIRE(r.val_nn_dtw_m.size() == 3);
  const nlohmann::json meta = nlohmann::json::parse(modelMetadata(smallData(), o, r));
  CHECK(meta["training"]["select"] == "rollouts");
  const EpochStats& kept = r.history[static_cast<std::size_t>(r.best_epoch - 1)];
  for (int m = 0; m < 3; ++m) {
    const std::string name = smallData().movement_names[static_cast<std::size_t>(m)];
    CHECK(meta["result"]["rollouts"][name]["dtw_m"].get<double>() == kept.rollouts[static_cast<std::size_t>(m)].dtw_m);
  }
  CHECK(meta["result"]["makes_movement"] == kept.makes_movement);
  CHECK(meta["result"]["movements_made"] == kept.movements_made);
  CHECK(meta["result"]["val_nn_dtw_m"].size() == 3);
  CHECK_MESSAGE(a == trainBytes(o), "two runs with seed 43 gave different bytes");

  // Refused where it cannot hold: reference mode needs a human; the runtime's step is compiled
  // for the paper and small computations only.
  TrainOptions reference = o;
  reference.conditioning = Conditioning::kReference;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), reference, nullptr), doctest::Contains("autonomous"), UserError);
  TrainOptions window = o;
  window.arch.window = 9;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), window, nullptr), doctest::Contains("runtime's step"), UserError);
}
