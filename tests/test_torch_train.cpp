// Training the policy with libtorch: the module is the manifest, training is deterministic for a
// seed, the exported file reads back to the module's tensors, the loss goes down, early
// stopping exports the best epoch, the attention record follows docs/policy.md.
#include "nao/controller.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "support/small_policy_data.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>

using namespace nao;
using namespace nao::tools;

namespace {

using nao::test::smallData;
using nao::test::smallOptions;
using nao::test::smallSim;

// The linear AR baseline evaluate fits for movement m: `data`'s training-split f, order chosen on
// its validation split's.
LinearArModel expectedLinearAr(const PolicyData& data, const PolicySplit& split, int m) {
  std::vector<std::vector<JointVector>> tr, va;
  for (int d : split.train)
    if (data.demos[static_cast<std::size_t>(d)].movement == m) tr.push_back(data.demos[static_cast<std::size_t>(d)].f);
  for (int d : split.val)
    if (data.demos[static_cast<std::size_t>(d)].movement == m) va.push_back(data.demos[static_cast<std::size_t>(d)].f);
  return fitLinearAr(tr, va, kMaxLinearArOrder);
}

std::vector<TrainedJoint> urdfJoints() { return trainedJoints(loadArmModel(nao::test::kUrdfPath)); }

std::vector<std::uint8_t> trainBytes(const TrainOptions& o, TrainResult* out = nullptr) {
  TrainResult r = trainPolicy(smallData(), smallSim(), o, nullptr);
  std::vector<std::uint8_t> bytes = encodeModel(modelHeader(smallData(), o, r, urdfJoints()), manifestFloats(r.net));
  if (out) *out = r;
  return bytes;
}

}  // namespace

TEST_CASE("the torch module's tensors are the manifest: same names, shapes and order, nothing else") {
  for (const PolicyArch& arch : {smallArch(), paperArch()})
    for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
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
      CHECK(buffers == std::set<std::string>{"norm.q_mean", "norm.q_std", "norm.a_mean", "norm.a_std", "norm.r_mean",
                                             "norm.r_std", "centroids"});
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
                 torch::randn({n_batch, n_ticks, n_joints}), torch::tensor({0, 2}, torch::kInt64), torch::Tensor()};
  PolicyAttention att;
  const torch::Tensor out = net->forward(in, &att);
  CHECK(out.sizes().vec() == std::vector<std::int64_t>{n_batch, n_ticks, n_joints});
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
                 torch::tensor({1}, torch::kInt64), torch::Tensor()};
  const torch::Tensor full = net->forward(in);
  const std::int64_t cut = arch.window + 1;
  PolicyBatch prefix{in.qn.slice(1, 0, cut), in.an.slice(1, 0, cut), in.rn.slice(1, 0, cut), in.movement, torch::Tensor()};
  CHECK((net->forward(prefix) - full.slice(1, 0, cut)).abs().max().item<float>() < 1e-5f);
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
                     torch::tensor({0, 2}, torch::kInt64), torch::Tensor()};
      const torch::Tensor target = torch::randn({2, n_ticks, 5});
      torch::Tensor out[2];
      std::vector<torch::Tensor> grad[2];
      PolicyAttention att[2];
      const WindowLayout layouts[2] = {WindowLayout::kFull, WindowLayout::kBlocked};
      for (int l = 0; l < 2; ++l) {
        net->window_layout = layouts[l];
        for (const torch::Tensor& p : params) p.mutable_grad() = torch::Tensor();
        out[l] = net->forward(in);
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
                 torch::tensor({0, 2}, torch::kInt64), torch::Tensor()};
  PolicyBatch other_ref = in;
  other_ref.rn = torch::randn({2, 6, 5});
  CHECK_FALSE(torch::equal(ref->forward(in), ref->forward(other_ref)));
  CHECK(torch::equal(aut->forward(in), aut->forward(other_ref)));
  // The step rows: zero and frozen in reference mode (see the manifest test), used in autonomous.
  CHECK(ref->step_emb.abs().max().item<float>() == 0.0f);
  const torch::Tensor with_steps = aut->forward(in);
  const torch::Tensor saved = aut->step_emb.clone();
  aut->step_emb.zero_();
  const torch::Tensor without_steps = aut->forward(in);
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
  CHECK(file.header.metadata_json.find("time") == std::string::npos);
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
  CHECK(r.val.normalised == r.history[static_cast<std::size_t>(r.best_epoch - 1)].val_loss);
  ExecutionOptions clean = o.execution;
  clean.noisy_rollouts = 0;
  CHECK(evaluatePolicy(r.net, executeDemos(smallData(), r.split.val, smallSim(), clean, o.seed)).normalised ==
        r.val.normalised);
  CHECK(static_cast<int>(r.history.size()) <= std::min(o.max_epochs, r.best_epoch + o.patience));
}

namespace {

torch::Tensor stacked(const std::vector<JointVector>& v) {
  torch::Tensor t = torch::empty({1, static_cast<std::int64_t>(v.size()), kNumJoints}, torch::kFloat);
  auto acc = t.accessor<float, 3>();
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int j = 0; j < kNumJoints; ++j) acc[0][static_cast<std::int64_t>(i)][j] = static_cast<float>(v[i][j]);
  return t;
}

}  // namespace

TEST_CASE("DAgger rollouts execute the net's own action (libtorch's forward on the recorded inputs, clamped as the controller does)") {
  const ArmModel& arm = smallSim().arm;
  const double period = smallSim().params.dt_s * smallSim().params.substeps_per_tick;
  const std::vector<int> demos = {0, 5, 10};
  ExecutionOptions clean;
  clean.noisy_rollouts = 0;
  const NormStats stats = normStats(executeDemos(smallData(), demos, smallSim(), clean, 1));
  // Autonomous with phase steps too: the runtime's step rows (floor(t·P / L), L the
  // demonstration's samples) must be the ones libtorch's forward uses.
  const std::vector<std::pair<Conditioning, int>> cases = {
      {Conditioning::kAutonomous, 0}, {Conditioning::kReference, 0}, {Conditioning::kAutonomous, 37}};
  std::vector<std::vector<JointVector>> phase0_q;
  for (const auto& [c, phase] : cases) {
    INFO(std::string(conditioningName(c)) << ", phase steps " << phase);
    torch::manual_seed(7);
    PolicyNet net(smallArch(), c);
    {
      // Away from the initialisation so that the actions are large enough to reach the clamp.
      torch::NoGradGuard no_grad;
      for (auto& p : net->parameters())
        if (p.requires_grad()) p.add_(torch::randn_like(p) * 0.2);
    }
    net->setNormalisation(stats);
    net->setCentroids(smallData().centroids);
    net->residual_gain = c == Conditioning::kReference ? 1.0894 : 0.0;
    net->phase_ticks = phase;
    net->eval();
    const std::vector<PolicySequence> seqs = daggerRollouts(smallData(), demos, smallSim(), clean, net, 1);
    if (c == Conditioning::kAutonomous && phase == 0)
      for (const PolicySequence& s : seqs) phase0_q.push_back(s.q);
    if (phase > 0)  // the phase changes what the net does
      for (std::size_t i = 0; i < seqs.size(); ++i) CHECK(seqs[i].q != phase0_q.at(i));
    REQUIRE(seqs.size() == demos.size());
    torch::NoGradGuard no_grad;
    double worst = 0.0, largest_action = 0.0, drift = 0.0;
    std::size_t saturated = 0;
    for (const PolicySequence& s : seqs) {
      CHECK(s.rollout == -1);
      const auto samples = static_cast<std::int64_t>(smallData().demos[static_cast<std::size_t>(s.demo)].f.size());
      const torch::Tensor act = net->act(stacked(s.q), stacked(s.a_prev), stacked(s.r),
                                         torch::tensor({static_cast<std::int64_t>(s.movement)}), nullptr,
                                         torch::tensor({samples}))
                                    .contiguous();
      auto a = act.accessor<float, 3>();
      for (std::size_t t = 0; t + 1 < s.ticks(); ++t)
        for (int j = 0; j < kNumJoints; ++j) {
          const double step = arm.v_max[j] * period;
          const double lo = std::max(arm.q_min[j], s.q[t][j] - step), hi = std::min(arm.q_max[j], s.q[t][j] + step);
          const double want = s.q[t][j] + a[0][static_cast<std::int64_t>(t)][j];
          const double cmd = std::clamp(want, std::min(lo, hi), std::max(lo, hi));
          if (cmd != want) ++saturated;
          largest_action = std::max(largest_action, std::abs(static_cast<double>(a[0][static_cast<std::int64_t>(t)][j])));
          worst = std::max(worst, std::abs(s.q[t][j] + s.a_prev[t + 1][j] - cmd));
        }
      drift = std::max(drift, s.drift_rad);
    }
    MESSAGE(std::string(conditioningName(c)) << ": executed vs libtorch's clamped action " << worst << " rad, largest action "
                                << largest_action << " rad, " << saturated << " clamped joint-ticks, drift " << drift << " rad");
    CHECK(worst < 1e-5);
    CHECK(largest_action > 1e-3);
    CHECK(drift > 1e-3);
  }
}

TEST_CASE("training with one DAgger round adds one policy rollout per training demonstration and stays deterministic") {
  TrainOptions o = smallOptions(41, 3);
  o.conditioning = Conditioning::kAutonomous;
  o.dagger_rounds = 1;
  o.dagger_start = 1;
  TrainResult r;
  const std::vector<std::uint8_t> a = trainBytes(o, &r);
  REQUIRE(r.dagger.size() == 1);
  const DaggerRound& round = r.dagger.front();
  std::size_t demo_ticks = 0;
  for (int d : r.split.train) demo_ticks += smallData().demos[static_cast<std::size_t>(d)].f.size() - 1;
  MESSAGE("DAgger round (small config, " << round.sequences << " demos, " << round.ticks << " ticks): " << round.seconds
                                         << " s, drift " << round.drift_rad << " rad");
  CHECK(round.after_epoch == 1);
  CHECK(round.sequences == r.split.train.size());
  CHECK(round.ticks == demo_ticks);
  // Epoch 1 trains on the executed rollouts, epochs 2 and 3 on those plus the round's.
  REQUIRE(r.history.size() == 3);
  CHECK(r.history[0].samples == r.train_samples);
  CHECK(r.history[1].samples == r.train_samples + round.ticks);
  CHECK(r.history[2].samples == r.train_samples + round.ticks);
  const nlohmann::json meta = nlohmann::json::parse(modelMetadata(smallData(), o, r));
  CHECK(meta["training"]["dagger"]["rounds"] == 1);
  CHECK(meta["training"]["dagger"]["run"][0]["sequences"] == round.sequences);
  CHECK(modelCard(smallData(), o, r, "test", "m.bin").find("| DAgger | 1 round") != std::string::npos);

  const std::vector<std::uint8_t> b = trainBytes(o);
  CHECK_MESSAGE(a == b, "two DAgger runs with seed 41 gave different bytes");
  // Off: no DAgger key (older files keep their bytes) and other weights.
  TrainOptions off = o;
  off.dagger_rounds = 0;
  TrainResult r_off;
  const std::vector<std::uint8_t> c = trainBytes(off, &r_off);
  CHECK(r_off.dagger.empty());
  CHECK(modelMetadata(smallData(), off, r_off).find("dagger") == std::string::npos);
  // Epoch 1 is the same run; epoch 2 trained on other data.
  CHECK(r_off.history[0].val_loss == r.history[0].val_loss);
  CHECK(r_off.history[1].val_loss != r.history[1].val_loss);
  CHECK(a != c);
  CHECK(round.expert_ticks == 0);  // pure: the policy executes every tick

  // β-mixed: about half the round's ticks executed by the expert, recorded; other data again.
  TrainOptions mixed = o;
  mixed.execution.dagger_beta = 0.5;
  TrainResult r_mixed;
  const std::vector<std::uint8_t> m = trainBytes(mixed, &r_mixed);
  REQUIRE(r_mixed.dagger.size() == 1);
  const DaggerRound& mr = r_mixed.dagger.front();
  MESSAGE("beta 0.5: " << mr.expert_ticks << " of " << mr.ticks << " ticks by the expert, drift " << mr.drift_rad
                       << " rad (pure: " << round.drift_rad << " rad)");
  CHECK(mr.ticks == round.ticks);
  CHECK(mr.expert_ticks > mr.ticks / 4);
  CHECK(mr.expert_ticks < mr.ticks * 3 / 4);
  CHECK(r_mixed.history[0].val_loss == r.history[0].val_loss);
  CHECK(m != a);
  const nlohmann::json mm = nlohmann::json::parse(modelMetadata(smallData(), mixed, r_mixed));
  CHECK(mm["training"]["dagger"]["beta"] == 0.5);
  CHECK(mm["training"]["dagger"]["run"][0]["expert_ticks"] == mr.expert_ticks);
  CHECK(meta["training"]["dagger"].find("beta") == meta["training"]["dagger"].end());
  CHECK(modelCard(smallData(), mixed, r_mixed, "test", "m.bin").find("beta-mixed rollouts, beta 0.5^round") != std::string::npos);

  // A drift bound: fewer ticks join, recorded.
  TrainOptions bounded = mixed;
  bounded.execution.dagger_max_drift_rad = 0.02;
  TrainResult r_bounded;
  const std::vector<std::uint8_t> bb = trainBytes(bounded, &r_bounded);
  REQUIRE(r_bounded.dagger.size() == 1);
  MESSAGE("max drift 0.02 rad: " << r_bounded.dagger.front().ticks << " of " << mr.ticks << " ticks kept");
  CHECK(r_bounded.dagger.front().ticks < mr.ticks);
  CHECK(r_bounded.dagger.front().ticks > 0);
  CHECK(bb != m);
  CHECK(nlohmann::json::parse(modelMetadata(smallData(), bounded, r_bounded))["training"]["dagger"]["max_drift_rad"] == 0.02);
  CHECK(modelCard(smallData(), bounded, r_bounded, "test", "m.bin").find("each ended where its drift first exceeds 0.02 rad") !=
        std::string::npos);

  // Aligned labels (the pool is the training split): the same states as the pure round (no β,
  // no bound), other labels, so other weights; recorded in the metadata and the card.
  TrainOptions aligned = o;
  aligned.execution.dagger_align_band = 3;
  aligned.execution.dagger_return = 0.5;
  TrainResult r_aligned;
  const std::vector<std::uint8_t> al = trainBytes(aligned, &r_aligned);
  REQUIRE(r_aligned.dagger.size() == 1);
  CHECK(r_aligned.dagger.front().ticks == round.ticks);
  CHECK(r_aligned.dagger.front().drift_rad == round.drift_rad);
  CHECK(r_aligned.history[0].val_loss == r.history[0].val_loss);
  CHECK(r_aligned.history[1].train_loss != r.history[1].train_loss);
  CHECK(al != a);
  const nlohmann::json ma = nlohmann::json::parse(modelMetadata(smallData(), aligned, r_aligned));
  CHECK(ma["training"]["dagger"]["align_band_ticks"] == 3);
  CHECK(ma["training"]["dagger"]["return"] == 0.5);
  CHECK(meta["training"]["dagger"].find("align_band_ticks") == meta["training"]["dagger"].end());
  CHECK(modelCard(smallData(), aligned, r_aligned, "test", "m.bin").find("within 3 ticks of the clock, returning 0.5") !=
        std::string::npos);
  // Aligned commands: other labels again.
  TrainOptions commanded = aligned;
  commanded.execution.dagger_align_label = ExecutionOptions::AlignLabel::kCommand;
  TrainResult r_commanded;
  const std::vector<std::uint8_t> co = trainBytes(commanded, &r_commanded);
  CHECK(r_commanded.dagger.front().ticks == round.ticks);
  CHECK(co != al);
  CHECK(co != a);
  const nlohmann::json mc = nlohmann::json::parse(modelMetadata(smallData(), commanded, r_commanded));
  CHECK(mc["training"]["dagger"]["labels"].get<std::string>().find("command") != std::string::npos);
  CHECK(modelCard(smallData(), commanded, r_commanded, "test", "m.bin").find("the clean execution's command") !=
        std::string::npos);
}

TEST_CASE("DAgger is refused with --resume, a beta of 1 and for an architecture the runtime is not compiled for") {
  TrainOptions o = smallOptions(1, 1);
  o.dagger_rounds = 1;
  TrainOptions resume = o;
  resume.resume = "/nonexistent/checkpoint.pt";
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), resume, nullptr), doctest::Contains("--resume"), UserError);
  TrainOptions window = o;
  window.arch.window = 9;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), window, nullptr), doctest::Contains("architecture"), UserError);
  TrainOptions start = o;
  start.dagger_start = 0;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), start, nullptr), doctest::Contains("start"), UserError);
  TrainOptions beta = o;
  beta.execution.dagger_beta = 1.0;  // the policy would never act
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), beta, nullptr), doctest::Contains("beta"), UserError);
  // Without DAgger the same window trains (the refusal is DAgger's).
  window.dagger_rounds = 0;
  CHECK_NOTHROW(trainPolicy(smallData(), smallSim(), window, nullptr));
}

TEST_CASE("over the linear AR base the untrained net is the baseline; rollout selection exports the epoch with the lowest rollout DTW") {
  TrainOptions o = smallOptions(43, 3);
  o.conditioning = Conditioning::kAutonomous;
  o.ar_residual = true;
  o.select_by_rollout = true;
  TrainResult r;
  const std::vector<std::uint8_t> a = trainBytes(o, &r);
  REQUIRE(r.net->linearAr().size() == 3);

  // The base is the baseline evaluate fits: the training split's f, order on the validation split's.
  const PolicyData& data = smallData();
  for (int m = 0; m < 3; ++m) {
    const LinearArModel expect = expectedLinearAr(data, r.split, m);
    for (int j = 0; j < kNumJoints; ++j) {
      const LinearArJoint& got = r.net->linearAr()[static_cast<std::size_t>(m)].joints[static_cast<std::size_t>(j)];
      CHECK(got.order == expect.joints[static_cast<std::size_t>(j)].order);
      CHECK(got.c == expect.joints[static_cast<std::size_t>(j)].c);
      CHECK(got.beta == expect.joints[static_cast<std::size_t>(j)].beta);
      CHECK(got.alpha == expect.joints[static_cast<std::size_t>(j)].alpha);
    }
  }

  // The base in libtorch is linearArAction (double, toolchain) in float: on a demonstration's f.
  {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(r.split.val.front())];
    const std::int64_t n = static_cast<std::int64_t>(demo.f.size()) - 1;
    torch::Tensor q = torch::empty({1, n, kNumJoints}), a_prev = torch::zeros({1, n, kNumJoints});
    for (std::int64_t t = 0; t < n; ++t)
      for (int j = 0; j < kNumJoints; ++j) {
        q[0][t][j] = static_cast<float>(demo.f[static_cast<std::size_t>(t)][j]);
        if (t > 0) a_prev[0][t][j] = static_cast<float>(demo.f[static_cast<std::size_t>(t)][j] - demo.f[static_cast<std::size_t>(t - 1)][j]);
      }
    const torch::Tensor base =
        r.net->linearArBase(q, a_prev, torch::tensor({static_cast<std::int64_t>(demo.movement)}, torch::kInt64));
    double worst = 0.0, largest = 0.0;
    std::vector<JointVector> past;
    for (std::int64_t t = 0; t < n; ++t) {
      const JointVector expect = linearArAction(r.net->linearAr()[static_cast<std::size_t>(demo.movement)],
                                                demo.f[static_cast<std::size_t>(t)], past);
      for (int j = 0; j < kNumJoints; ++j) {
        worst = std::max(worst, std::abs(static_cast<double>(base[0][t][j].item<float>()) - expect[j]));
        largest = std::max(largest, std::abs(expect[j]));
      }
      past.insert(past.begin(), JointVector(demo.f[static_cast<std::size_t>(t + 1)] - demo.f[static_cast<std::size_t>(t)]));
    }
    CHECK(worst < 1e-5);
    CHECK(largest > 1e-3);
  }

  // Epoch 0 is scored (the untrained net: the baseline, reported, not exported), and the kept
  // epoch is the argmin of the trained ones.
  REQUIRE(r.epoch0.epoch == 0);
  REQUIRE(std::isfinite(r.epoch0.rollout_dtw_m));
  int argmin = 0;
  double best = std::numeric_limits<double>::infinity();
  for (const EpochStats& e : r.history) {
    REQUIRE(e.rollout_dtw_per_movement_m.size() == 3);
    if (e.rollout_dtw_m < best) {
      best = e.rollout_dtw_m;
      argmin = e.epoch;
    }
  }
  CHECK(r.best_epoch == argmin);
  // Epochs differ in their rollouts (the score can tell them apart).
  CHECK(r.history.front().rollout_dtw_m != r.epoch0.rollout_dtw_m);

  // The metadata carries the base nao_rt adds back, and the selection.
  const nlohmann::json meta = nlohmann::json::parse(modelMetadata(data, o, r));
  CHECK(meta["training"]["select"] == "rollout_dtw");
  REQUIRE(meta["training"]["linear_ar"].size() == 3);
  CHECK(meta["training"]["linear_ar"][1][2]["beta"].get<double>() == r.net->linearAr()[1].joints[2].beta);
  CHECK(meta["result"]["val_nn_dtw_m"].size() == 3);
  CHECK(meta["result"]["epoch0_rollout_dtw_m"].size() == 3);
  CHECK(meta["result"]["rollout_dtw_m"].size() == 3);
  const std::string card = modelCard(data, o, r, "test", "m.bin");
  CHECK(card.find("| linear AR base |") != std::string::npos);
  CHECK(card.find("| model selection | rollout DTW") != std::string::npos);

  CHECK_MESSAGE(a == trainBytes(o), "two runs with seed 43 gave different bytes");
}

TEST_CASE("phase steps: the step row follows the demonstration's phase, recorded, and refused where they cannot hold") {
  // The controller's rule, which the trainer's rollouts use too: floor(t·P / L), clamped.
  ControllerParams pace;
  CHECK(policyStep(5, pace, 256) == 5);
  CHECK(policyStep(300, pace, 256) == 255);
  pace.phase_ticks = 150;
  pace.run_ticks = 100;
  CHECK(policyStep(0, pace, 256) == 0);
  CHECK(policyStep(1, pace, 256) == 1);    // 1.5
  CHECK(policyStep(2, pace, 256) == 3);
  CHECK(policyStep(99, pace, 256) == 148);  // 148.5
  pace.run_ticks = 300;
  CHECK(policyStep(299, pace, 256) == 149);
  CHECK(policyStep(1, pace, 256) == 0);
  pace.phase_ticks = 1000;
  CHECK(policyStep(299, pace, 256) == 255);

  TrainOptions o = smallOptions(53, 2);
  o.conditioning = Conditioning::kAutonomous;
  TrainResult r0;
  const std::vector<std::uint8_t> a = trainBytes(o, &r0);
  TrainOptions phased = o;
  phased.phase_ticks = 40;
  TrainResult r1;
  const std::vector<std::uint8_t> b = trainBytes(phased, &r1);
  CHECK(a != b);
  CHECK(r1.history[0].val_loss != r0.history[0].val_loss);
  CHECK(b == trainBytes(phased));  // deterministic
  CHECK(nlohmann::json::parse(modelMetadata(smallData(), phased, r1))["training"]["phase_ticks"] == 40);
  CHECK(modelMetadata(smallData(), o, r0).find("phase_ticks") == std::string::npos);

  TrainOptions reference = phased;
  reference.conditioning = Conditioning::kReference;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), reference, nullptr), doctest::Contains("autonomous"), UserError);
  TrainOptions cut = phased;
  cut.dagger_rounds = 1;
  cut.execution.dagger_max_drift_rad = 0.1;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), cut, nullptr), doctest::Contains("--dagger-max-drift"), UserError);
}

TEST_CASE("canonical pace: trained on the paced demonstrations (AR base included), scored against them as they are") {
  TrainOptions o = smallOptions(59, 1);
  o.val_fraction = 0.5;  // two validation demonstrations per movement: a nearest neighbour each
  o.conditioning = Conditioning::kAutonomous;
  o.ar_residual = true;
  o.select_by_rollout = true;
  TrainOptions paced = o;
  paced.canonical_pace = PaceMethod::kDtw;
  TrainResult r0, r1;
  const std::vector<std::uint8_t> a = trainBytes(o, &r0);
  const std::vector<std::uint8_t> b = trainBytes(paced, &r1);
  CHECK(a != b);
  const PolicyData& data = smallData();
  REQUIRE(r1.split.train == r0.split.train);
  const std::vector<int> tmpl = paceTemplates(data, r1.split.train);
  CHECK(r1.pace_templates == tmpl);
  CHECK(r0.pace_templates.empty());
  // The small set's demonstrations differ in length, so pacing changes something to learn.
  bool longer = false;
  for (int d : r1.split.train) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    longer = longer || demo.f.size() > data.demos[static_cast<std::size_t>(tmpl[static_cast<std::size_t>(demo.movement)])].f.size();
  }
  REQUIRE(longer);
  // The AR base is fitted on the paced trajectories (as evaluate fits it for this model).
  const PolicyData p = pacedData(data, tmpl, PaceMethod::kDtw);
  for (int m = 0; m < 3; ++m) {
    const LinearArModel expect = expectedLinearAr(p, r1.split, m);
    for (int j = 0; j < kNumJoints; ++j) {
      const LinearArJoint& got = r1.net->linearAr()[static_cast<std::size_t>(m)].joints[static_cast<std::size_t>(j)];
      CHECK(got.beta == expect.joints[static_cast<std::size_t>(j)].beta);
      CHECK(got.alpha == expect.joints[static_cast<std::size_t>(j)].alpha);
    }
  }
  // Validation targets are paced too (other baselines), the rollouts' yardstick is not.
  CHECK(r1.val_baselines.repeat_last != r0.val_baselines.repeat_last);
  REQUIRE(r1.val_nn_dtw_m.size() == 3);
  for (double x : r1.val_nn_dtw_m) CHECK(std::isfinite(x));
  CHECK(r1.val_nn_dtw_m == r0.val_nn_dtw_m);
  const nlohmann::json meta = nlohmann::json::parse(modelMetadata(data, paced, r1));
  const nlohmann::json& cp = meta["training"]["canonical_pace"];
  CHECK(cp["method"] == "dtw");
  for (int m = 0; m < 3; ++m) {
    const PolicyDemo& t = data.demos[static_cast<std::size_t>(tmpl[static_cast<std::size_t>(m)])];
    CHECK(cp["templates"][m] == t.name);
    CHECK(cp["ticks"][m].get<std::size_t>() == t.f.size());
  }
  CHECK(modelMetadata(data, o, r0).find("canonical_pace") == std::string::npos);
  CHECK(modelCard(data, paced, r1, "test", "m.bin").find("| canonical pace | dtw") != std::string::npos);
  CHECK(b == trainBytes(paced));  // deterministic
  TrainOptions linear = paced;
  linear.canonical_pace = PaceMethod::kLinear;
  CHECK(trainBytes(linear) != b);

  TrainOptions reference = paced;
  reference.conditioning = Conditioning::kReference;
  reference.ar_residual = reference.select_by_rollout = false;
  CHECK_THROWS_WITH_AS(trainPolicy(data, smallSim(), reference, nullptr), doctest::Contains("autonomous"), UserError);
  TrainOptions both = paced;
  both.phase_ticks = 40;
  CHECK_THROWS_WITH_AS(trainPolicy(data, smallSim(), both, nullptr), doctest::Contains("--phase-steps"), UserError);
}
