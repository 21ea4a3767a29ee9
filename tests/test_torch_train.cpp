// Training the policy with libtorch: the module is the manifest, training is deterministic for a
// seed, the exported file reads back to the module's tensors, the loss goes down, early
// stopping exports the best epoch, the attention record follows docs/policy.md.
#include "nao/model_file.hpp"
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
#include <set>

using namespace nao;
using namespace nao::tools;

namespace {

using nao::test::smallData;
using nao::test::smallOptions;

std::vector<TrainedJoint> urdfJoints() { return trainedJoints(loadArmModel(nao::test::kUrdfPath)); }

std::vector<std::uint8_t> trainBytes(const TrainOptions& o, TrainResult* out = nullptr) {
  TrainResult r = trainPolicy(smallData(), o, nullptr);
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

TEST_CASE("the attention record follows docs/policy.md: rows sum to 1, causal self-attention, the norm-based score") {
  torch::manual_seed(3);
  const PolicyArch arch = smallArch();
  const PolicyNet net(arch, Conditioning::kReference);
  {
    // Non-trivial biases so that the check sees them.
    torch::NoGradGuard no_grad;
    for (auto& p : net->parameters())
      if (p.dim() == 1 && p.requires_grad()) p.add_(torch::randn_like(p) * 0.1);
  }
  const std::int64_t n_batch = 3, n_joints = arch.tokens, d = arch.d_model, n_heads = arch.heads, d_h = d / n_heads;
  PolicyBatch in{torch::randn({n_batch, n_joints}), torch::randn({n_batch, n_joints}), torch::randn({n_batch, n_joints}),
                 torch::tensor({0, 1, 2}, torch::kInt64), torch::tensor({0, 5, 255}, torch::kInt64)};
  PolicyAttention att;
  const torch::Tensor out = net->forward(in, &att);
  CHECK(out.sizes().vec() == std::vector<std::int64_t>{n_batch, n_joints});
  REQUIRE(att.cross.size() == static_cast<std::size_t>(arch.decoder_layers));
  for (const torch::Tensor& a : att.cross) {
    CHECK(a.sizes().vec() == std::vector<std::int64_t>{n_batch, n_heads, n_joints, n_joints});
    CHECK((a.sum(-1) - 1).abs().max().item<float>() < 1e-6f);
  }
  CHECK(att.cross_out.sizes().vec() == std::vector<std::int64_t>{n_batch, n_joints, d});

  // The score, recomputed by loops from the module's own tensors (memory recomputed here).
  torch::NoGradGuard no_grad;
  torch::Tensor x = net->embed_in->forward(torch::stack({in.qn, in.an, in.rn}, -1)) + net->joint_enc +
                    net->movement_emb.index_select(0, in.movement).unsqueeze(1) +
                    net->step_emb.index_select(0, in.step).unsqueeze(1);
  for (const EncoderLayer& l : net->enc) x = l->forward(x);
  const torch::Tensor memory = net->enc_norm->forward(x);
  const Attention& cross = net->dec.back()->cross;
  const torch::Tensor v = memory.matmul(cross->wv) + cross->bv;  // [B,J,d]
  const torch::Tensor& alpha = att.cross.back();
  for (std::int64_t b = 0; b < n_batch; ++b)
    for (std::int64_t j = 0; j < n_joints; ++j) {
      double score = 0.0;
      for (std::int64_t i = 0; i < n_joints; ++i) {
        torch::Tensor sum = torch::zeros({d});
        for (std::int64_t h = 0; h < n_heads; ++h) {
          const torch::Tensor f_h = v[b][j].slice(0, h * d_h, (h + 1) * d_h).matmul(cross->wo.slice(0, h * d_h, (h + 1) * d_h));
          sum += alpha[b][h][i][j] * f_h;
        }
        score += sum.norm().item<double>();
      }
      CHECK(att.score[b][j].item<double>() == doctest::Approx(score).epsilon(1e-5));
    }

  // Causal self-attention: query i gets weight 0 on keys above i, the rest sums to 1.
  torch::Tensor self_alpha;
  const torch::Tensor tokens = torch::randn({n_batch, n_joints, d});
  net->dec.front()->self->forward(tokens, tokens, true, &self_alpha);
  CHECK(self_alpha.triu(1).abs().max().item<float>() == 0.0f);
  CHECK((self_alpha.sum(-1) - 1).abs().max().item<float>() < 1e-6f);
  CHECK(self_alpha.tril(-1).abs().max().item<float>() > 0.0f);
}

TEST_CASE("reference mode ignores the step, autonomous mode ignores the reference") {
  torch::manual_seed(4);
  const PolicyArch arch = smallArch();
  const PolicyNet ref(arch, Conditioning::kReference), aut(arch, Conditioning::kAutonomous);
  torch::NoGradGuard no_grad;
  PolicyBatch in{torch::randn({2, 5}), torch::randn({2, 5}), torch::randn({2, 5}), torch::tensor({0, 2}, torch::kInt64),
                 torch::tensor({3, 7}, torch::kInt64)};
  PolicyBatch other_step = in, other_ref = in;
  other_step.step = torch::tensor({100, 0}, torch::kInt64);
  other_ref.rn = torch::randn({2, 5});
  CHECK(torch::equal(ref->forward(in), ref->forward(other_step)));
  CHECK_FALSE(torch::equal(ref->forward(in), ref->forward(other_ref)));
  CHECK(torch::equal(aut->forward(in), aut->forward(other_ref)));
  CHECK_FALSE(torch::equal(aut->forward(in), aut->forward(other_step)));
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
  const TrainResult r = trainPolicy(smallData(), o, nullptr);
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
  const TrainResult r = trainPolicy(smallData(), o, nullptr);
  REQUIRE(r.best_epoch >= 1);
  double best = 1e300;
  for (const EpochStats& e : r.history) best = std::min(best, e.val_loss);
  CHECK(r.history[static_cast<std::size_t>(r.best_epoch - 1)].val_loss == best);
  CHECK(r.val.normalised == r.history[static_cast<std::size_t>(r.best_epoch - 1)].val_loss);
  CHECK(evaluatePolicy(r.net, buildSamples(smallData(), r.split.val, o.arch.max_steps)).normalised == r.val.normalised);
  CHECK(static_cast<int>(r.history.size()) <= std::min(o.max_epochs, r.best_epoch + o.patience));
}
