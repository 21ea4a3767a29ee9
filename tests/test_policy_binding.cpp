// Binding a policy's weights (nao/policy.hpp): bindPolicyWeights views each manifest tensor in
// place with the head's extents, refuses what the runtime cannot run, and bindPolicyWeightsAt
// binds the same views from a model.bin image; model.bin format 3 carries the chunk.
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "support/policy_test_model.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

using namespace nao;

namespace {

using nao::test::archOf;
using nao::test::bitwiseEqual;
using nao::test::Fixture;
using nao::test::randomInput;
using nao::test::randomModel;
using nao::test::TestModel;

}  // namespace

TEST_CASE("bindPolicyWeights views each tensor in place: Eigen [out, in] is the manifest's [in, out]") {
  Fixture<SmallPolicyDims> f(5, Conditioning::kReference, false);
  const std::vector<float>& wo = f.model["dec.1.cross.wo"];
  const std::vector<float>& w1 = f.model["enc.0.ffn.1.weight"];  // [64, 64]
  const std::vector<float>& w3 = f.model["enc.1.ffn.3.weight"];  // [64, 32]
  const std::vector<float>& c = f.model["centroids"];            // [3, 10, 5]
  CHECK(f.w.dec[1].cross.wo.data() == wo.data());
  CHECK(f.w.dec[1].cross.wo(3, 7) == wo[7 * 32 + 3]);
  CHECK(f.w.enc[0].ffn.w1(5, 60) == w1[60 * 64 + 5]);
  CHECK(f.w.enc[1].ffn.w3(31, 2) == w3[2 * 32 + 31]);
  CHECK(f.w.centroids(4, 2 * 10 + 7) == c[(2 * 10 + 7) * 5 + 4]);
  CHECK(f.w.embed_step.data() == f.model["embed.step"].data());
  CHECK(f.w.head_bias(0, 0) == f.model["head.bias"][0]);
  CHECK(f.w.head_weight(0, 17) == f.model["head.weight"][17]);  // [d, C = 1]
  CHECK(f.w.law_gain(3) == f.model["law.gain"][3]);
  CHECK(f.w.conditioning == Conditioning::kReference);
  CHECK((f.w.chunk == 1 && f.w.movements == 3 && f.w.clusters == 10 && f.w.max_steps == 256));
  CHECK(f.w.ensemble_weight[0][0] == 1.0f);
}

TEST_CASE("a chunked head's views: head.weight [C, d], head.bias [C], and the ensemble's weights from its decay") {
  constexpr int D = SmallPolicyDims::kDModel, C = 4;
  Fixture<SmallPolicyDims> f(6, Conditioning::kAutonomous, false, archOf<SmallPolicyDims>(C, 2, 7, 40));
  CHECK((f.w.chunk == C && f.w.movements == 2 && f.w.clusters == 7 && f.w.max_steps == 40));
  CHECK((f.w.embed_movement.cols() == 2 && f.w.embed_step.cols() == 40 && f.w.centroids.cols() == 14));
  const std::vector<float>& hw = f.model["head.weight"];  // [d, C]
  const std::vector<float>& hb = f.model["head.bias"];    // [C]
  REQUIRE((f.w.head_weight.rows() == C && f.w.head_weight.cols() == D));
  REQUIRE(f.w.head_bias.rows() == C);
  for (int c = 0; c < C; ++c) {
    for (int k = 0; k < D; k += 5) CHECK(f.w.head_weight(c, k) == hw[static_cast<std::size_t>(k * C + c)]);
    CHECK(f.w.head_bias(c) == hb[static_cast<std::size_t>(c)]);
  }
  // w_k ∝ exp(−decay k) over the k < n chunks that exist, rows summing to 1.
  const double decay = f.model["head.ensemble_decay"][0];
  REQUIRE(decay == doctest::Approx(0.3));
  for (int n = 1; n <= C; ++n) {
    double sum = 0.0, norm = 0.0;
    for (int k = 0; k < n; ++k) norm += std::exp(-decay * k);
    for (int k = 0; k < n; ++k) {
      const float wk = f.w.ensemble_weight[static_cast<std::size_t>(n - 1)][static_cast<std::size_t>(k)];
      CHECK(wk == doctest::Approx(std::exp(-decay * k) / norm).epsilon(1e-6));
      sum += wk;
    }
    CHECK(sum == doctest::Approx(1.0).epsilon(1e-6));
  }
}

TEST_CASE("bindPolicyWeights rejects a wrong tensor count, a null tensor, another computation, and a chunk beyond the runtime's") {
  const TestModel m = randomModel(smallArch(), 7, false);
  const std::vector<const float*> p = m.pointers();
  const Conditioning c = Conditioning::kReference;
  CHECK_NOTHROW(bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), smallArch(), c));
  CHECK_THROWS_AS(bindPolicyWeights<SmallPolicyDims>(p.data(), p.size() - 1, smallArch(), c), std::invalid_argument);
  CHECK_THROWS_AS(bindPolicyWeights<SmallPolicyDims>(p.data(), p.size() + 1, smallArch(), c), std::invalid_argument);
  // The small model's tensors are not a paper model, nor one with a chunk of 4 (its ensemble decay).
  CHECK_THROWS_AS(bindPolicyWeights<PaperPolicyDims>(p.data(), p.size(), smallArch(), c), std::invalid_argument);
  CHECK_THROWS_AS(bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), archOf<SmallPolicyDims>(4), c),
                  std::invalid_argument);
  // A chunk of 3 bound as one (the pointers carry no shapes: the file's table is checked
  // against the manifest by the reader, test_model_file).
  const TestModel m3 = randomModel(archOf<SmallPolicyDims>(3), 8, false);
  const std::vector<const float*> p3 = m3.pointers();
  CHECK_NOTHROW(bindPolicyWeights<SmallPolicyDims>(p3.data(), p3.size(), archOf<SmallPolicyDims>(3), c));
  std::vector<const float*> with_null = p;
  with_null[10] = nullptr;
  CHECK_THROWS_WITH_AS(bindPolicyWeights<SmallPolicyDims>(with_null.data(), with_null.size(), smallArch(), c),
                       doctest::Contains(m.manifest[10].name.c_str()), std::invalid_argument);

  CHECK_NOTHROW(checkPolicyArch<SmallPolicyDims>(smallArch()));
  CHECK_THROWS_AS(checkPolicyArch<PaperPolicyDims>(smallArch()), std::invalid_argument);
  // The tables and the head are the model's: any sizes bind to the same compiled dimensions.
  CHECK_NOTHROW(checkPolicyArch<SmallPolicyDims>(archOf<SmallPolicyDims>(kPolicyMaxChunk, 17, 3, 9)));
  CHECK_THROWS_WITH_AS(checkPolicyArch<SmallPolicyDims>(archOf<SmallPolicyDims>(kPolicyMaxChunk + 1)),
                       doctest::Contains("chunk 33"), std::invalid_argument);
  PolicyArch window = smallArch();
  window.window = 9;
  CHECK_THROWS_WITH_AS(checkPolicyArch<SmallPolicyDims>(window), doctest::Contains("window 9"), std::invalid_argument);
  PolicyArch four_ffn = paperArch();
  four_ffn.ffn_hidden = {512, 512, 512, 512};
  CHECK(archProblem(four_ffn).empty());  // a valid architecture, just not a compiled one
  CHECK_THROWS_WITH_AS(checkPolicyArch<PaperPolicyDims>(four_ffn), doctest::Contains("512-512-512-512"),
                       std::invalid_argument);
}

TEST_CASE("binding checks the manifest's roles: a matrix role on a view without an int8 copy, or none on one with it, is refused by name") {
  const TestModel m = randomModel(smallArch(), 7, false);
  const std::vector<const float*> p = m.pointers();
  PolicyWeights<SmallPolicyDims> w;
  detail::setPolicySizes(w, smallArch(), Conditioning::kReference, PolicyKernel::kSse);
  const std::vector<detail::WeightSlot> slots = detail::weightSlots(w);
  std::vector<TensorSpec> manifest = policyManifest(smallArch());
  CHECK_NOTHROW(detail::bindWeightSlots(slots, manifest, p.data(), p.size()));
  for (const char* name : {"enc.0.attn.wq", "enc.0.attn.bq"}) {
    std::vector<TensorSpec> flipped = manifest;
    for (TensorSpec& t : flipped)
      if (t.name == name) t.role = t.role == TensorRole::kMatrix ? TensorRole::kTrained : TensorRole::kMatrix;
    CHECK_THROWS_WITH_AS(detail::bindWeightSlots(slots, flipped, p.data(), p.size()),
                         doctest::Contains((std::string("tensor '") + name + "' is").c_str()), std::invalid_argument);
  }
}

namespace {

/// A model.bin image of `model` (manifest order), decoded.
ModelFile modelImage(const TestModel& model, const PolicyArch& arch, Conditioning c) {
  ModelHeader h;
  h.arch = arch;
  h.conditioning = c;
  for (int j = 0; j < arch.tokens; ++j) h.joints.push_back({"j" + std::to_string(j), -2.0, 2.0, 3.0});
  for (int m = 0; m < arch.movements; ++m) h.movement_names.push_back("m" + std::to_string(m));
  h.metadata_json = "{}";
  return decodeModel(encodeModel(h, model.data), "test.bin");
}

struct ViewShape {
  std::string name;
  const float* data;
  long rows, cols;
  bool operator==(const ViewShape& o) const { return name == o.name && data == o.data && rows == o.rows && cols == o.cols; }
};

template <class Dims>
std::vector<ViewShape> viewShapes(PolicyWeights<Dims>& w) {
  std::vector<ViewShape> out;
  detail::visitWeightViews(w, [&](const detail::ViewName& n, auto& view, auto&...) {
    out.push_back({n.str(), view.data(), static_cast<long>(view.rows()), static_cast<long>(view.cols())});
  });
  return out;
}

}  // namespace

TEST_CASE("bindPolicyWeightsAt on a model.bin image binds what bindPolicyWeights binds: every view, the head's extents, the same steps bit for bit") {
  using Dims = SmallPolicyDims;
  for (const PolicyArch& arch : {archOf<Dims>(), archOf<Dims>(5), archOf<Dims>(3, 2, 4, 30)}) {
    CAPTURE(arch.chunk);
    const TestModel model = randomModel(arch, 91, false);
    const ModelFile file = modelImage(model, arch, Conditioning::kAutonomous);
    std::vector<std::uint64_t> offsets;
    std::vector<TensorExtent> extents;
    std::vector<const float*> ptrs;
    for (std::size_t i = 0; i < file.tensors.size(); ++i) {
      offsets.push_back(file.tensors[i].offset);
      extents.push_back(viewExtent(file.tensors[i].spec));
      ptrs.push_back(file.data(i));
    }
    REQUIRE(offsets.size() == detail::policyViewCount<Dims>(arch.chunk));
    PolicyWeights<Dims> at =
        bindPolicyWeightsAt<Dims>(file.bytes.data(), offsets.data(), extents.data(), arch, Conditioning::kAutonomous);
    PolicyWeights<Dims> by_name = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, Conditioning::kAutonomous);
    const std::vector<ViewShape> a = viewShapes(at), b = viewShapes(by_name);
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) CHECK_MESSAGE(a[i] == b[i], a[i].name);
    CHECK(at.ensemble_weight == by_name.ensemble_weight);
    CHECK((at.chunk == arch.chunk && at.movements == arch.movements));
    std::mt19937_64 rng(92);
    const auto ws_at = makePolicyWorkspace<Dims>(), ws_name = makePolicyWorkspace<Dims>();
    for (int tk = 0; tk < 2 * Dims::kWindow; ++tk) {
      const PolicyInput in = randomInput(rng, 1, tk);
      CHECK(bitwiseEqual(stepPolicy(at, *ws_at, in), stepPolicy(by_name, *ws_name, in)));
    }
  }
}

TEST_CASE("model.bin format 3 carries the chunk: a chunked model round-trips, tensor for tensor, through a file") {
  using Dims = SmallPolicyDims;
  const PolicyArch arch = archOf<Dims>(3, 2, 4, 30);
  const TestModel model = randomModel(arch, 93, false);
  const ModelFile image = modelImage(model, arch, Conditioning::kAutonomous);
  CHECK(image.header.arch == arch);
  CHECK(image.header.arch.chunk == 3);
  CHECK(image.header.conditioning == Conditioning::kAutonomous);
  const std::string path = test::writeTempFile("policy_head_v3.bin", "");
  ModelHeader h = image.header;
  const std::uint64_t checksum = writeModelFile(path, h, model.data);
  const ModelFile file = readModelFile(path);
  CHECK(file.checksum == checksum);
  CHECK(file.header.arch == arch);
  REQUIRE(file.tensors.size() == model.manifest.size());
  for (std::size_t i = 0; i < file.tensors.size(); ++i) {
    CHECK(file.tensors[i].spec.name == model.manifest[i].name);
    CHECK(file.tensors[i].spec.shape == model.manifest[i].shape);
    CHECK(std::memcmp(file.data(i), model.data[i].data(), model.data[i].size() * sizeof(float)) == 0);
  }
  CHECK_NOTHROW(file.find("head.weight"));
  CHECK_NOTHROW(file.find("head.ensemble_decay"));
  CHECK_THROWS_AS(file.find("head.centers"), ModelFileError);  // no tensor of another head
  // The header and the tensors must agree: another chunk is another manifest.
  ModelHeader other = h;
  other.arch.chunk = 2;
  CHECK_THROWS_AS(encodeModel(other, model.data), ModelFileError);
}

TEST_CASE("a model.bin of format 2 is refused with one line naming the version") {
  using Dims = SmallPolicyDims;
  const TestModel model = randomModel(archOf<Dims>(), 94, false);
  ModelHeader h;
  h.arch = archOf<Dims>();
  for (int j = 0; j < 5; ++j) h.joints.push_back({"j" + std::to_string(j), -2.0, 2.0, 3.0});
  h.movement_names = {"m0", "m1", "m2"};
  h.metadata_json = "{}";
  std::vector<std::uint8_t> bytes = encodeModel(h, model.data);
  REQUIRE(bytes.size() > 12);
  CHECK(bytes[8] == 3);  // little-endian u32 after the 8-byte magic
  bytes[8] = 2;
  try {
    decodeModel(bytes, "old.bin");
    FAIL("a format-2 file was accepted");
  } catch (const ModelFileError& e) {
    const std::string what = e.what();
    CHECK(what == "old.bin: format version 2 is not supported (this build reads 3)");
    CHECK(what.find('\n') == std::string::npos);
  }
  const std::string path = test::writeTempFile("policy_head_v2.bin", std::string(bytes.begin(), bytes.end()));
  CHECK_THROWS_WITH_AS(readModelFile(path), doctest::Contains("format version 2"), ModelFileError);
}
