// nao_codegen: the generated sources describe exactly the model they embed, and an
// unchanged model rewrites nothing (cheap rebuilds).
#include "nao/codegen.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"

#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>

namespace {

namespace fs = std::filesystem;

nao::ModelHeader makeHeader(const nao::PolicyArch& arch) {
  nao::ModelHeader h;
  h.arch = arch;
  h.conditioning = nao::Conditioning::kAutonomous;
  h.joints = nao::trainedJoints(nao::loadArmModel(nao::test::kUrdfPath));
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = R"({"seed":11})";
  return h;
}

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

/// The numbers of `inline constexpr std::array<...> name = { ... };` in `text`.
std::vector<std::string> arrayItems(const std::string& text, const std::string& name) {
  const std::size_t at = text.find(" " + name + " = {");
  REQUIRE_MESSAGE(at != std::string::npos, name << " not in the generated header");
  const std::size_t open = text.find('{', at), close = text.find('}', at);
  std::vector<std::string> items;
  std::string item;
  for (std::size_t i = open + 1; i < close; ++i) {
    const char c = text[i];
    if (c == ',') {
      items.push_back(item);
      item.clear();
    } else if (c != ' ' && c != '\n') {
      item += c;
    }
  }
  if (!item.empty()) items.push_back(item);
  return items;
}

/// A fresh directory with a random small-architecture model at `path` and `out` for the
/// generated sources.
struct SmallModel {
  std::string path;
  fs::path out;
};
SmallModel smallModel(const std::string& name, std::uint64_t seed) {
  const fs::path dir = freshDir(name);
  const nao::PolicyArch arch = nao::smallArch();
  SmallModel m{(dir / "in.bin").string(), dir / "gen"};
  nao::writeModelFile(m.path, makeHeader(arch), nao::test::randomManifestTensors(arch, seed));
  return m;
}

}  // namespace

TEST_CASE("nao_codegen writes a config header, a dims header, an .incbin'ing .S and a copy of the model") {
  const fs::path dir = freshDir("codegen");
  const std::string model_path = (dir / "in.bin").string();
  const nao::PolicyArch arch = nao::smallArch();
  nao::writeModelFile(model_path, makeHeader(arch), nao::test::randomManifestTensors(arch, 5));
  const fs::path out = dir / "gen";

  const nao::codegen::Result r = nao::codegen::generate(model_path, out.string());
  CHECK(r.written.size() == 6);  // model.int8 and model.packed too: empty for fp32
  CHECK(r.unchanged.empty());
  const nao::ModelFile& m = r.model;

  // The copy is the model, byte for byte.
  const std::string copy = nao::test::readFile((out / "model.bin").string());
  CHECK(copy == std::string(m.bytes.begin(), m.bytes.end()));
  CHECK(nao::test::readFile((out / "model.int8").string()).empty());

  const std::string config = nao::test::readFile((out / "nao_model_config.hpp").string());
  for (const std::string line : {"namespace nao::compiled {", "inline constexpr int kDModel = 32;",
                                 "inline constexpr int kHeads = 4;", "inline constexpr int kHeadDim = 8;",
                                 "inline constexpr int kEncoderLayers = 2;", "inline constexpr int kDecoderLayers = 2;",
                                 "inline constexpr int kFfn0 = 64;", "inline constexpr int kFfn2 = 64;",
                                 "inline constexpr int kTokens = 5;", "inline constexpr int kMovements = 3;",
                                 "inline constexpr int kClusters = 10;", "inline constexpr int kMaxSteps = 256;",
                                 "inline constexpr int kWindow = 8;",
                                 "inline constexpr Conditioning kConditioning = Conditioning::kAutonomous;"})
    CHECK_MESSAGE(config.find(line) != std::string::npos, line);
  char checksum[64];
  std::snprintf(checksum, sizeof checksum, "kChecksum = 0x%016llxull;", static_cast<unsigned long long>(m.checksum));
  CHECK(config.find(checksum) != std::string::npos);
  CHECK(config.find("kParameterCount = " + std::to_string(nao::parameterCount(arch)) + ";") != std::string::npos);
  CHECK(config.find("inline constexpr bool kInt8Weights = false;") != std::string::npos);
  CHECK(config.find("inline constexpr bool kPackedWeights = false;") != std::string::npos);

  // Tensor names, offsets and counts: the file's table, in manifest order.
  const auto names = arrayItems(config, "kTensorNames");
  const auto offsets = arrayItems(config, "kTensorOffsets");
  const auto counts = arrayItems(config, "kTensorCounts");
  REQUIRE(names.size() == m.tensors.size());
  REQUIRE(offsets.size() == m.tensors.size());
  REQUIRE(counts.size() == m.tensors.size());
  for (std::size_t i = 0; i < m.tensors.size(); ++i) {
    CHECK(names[i] == "\"" + m.tensors[i].spec.name + "\"");
    CHECK(offsets[i] == std::to_string(m.tensors[i].offset) + "u");
    CHECK(counts[i] == std::to_string(m.tensors[i].spec.count()) + "u");
  }

  // Joint limits are written so that they read back exactly.
  const nao::ArmModel arm = nao::loadArmModel(nao::test::kUrdfPath);
  const auto lower = arrayItems(config, "kJointLower");
  const auto velocity = arrayItems(config, "kJointVelocity");
  REQUIRE(lower.size() == 5);
  for (int j = 0; j < nao::kNumJoints; ++j) {
    CHECK(std::strtod(lower[static_cast<std::size_t>(j)].c_str(), nullptr) == arm.q_min[j]);
    CHECK(std::strtod(velocity[static_cast<std::size_t>(j)].c_str(), nullptr) == arm.v_max[j]);
  }
  CHECK(arrayItems(config, "kMovementNames") == std::vector<std::string>{"\"elbow\"", "\"whole_arm\"", "\"wrist\""});

  const std::string dims = nao::test::readFile((out / "nao_model_dims.hpp").string());
  CHECK(dims.find("using Dims = nao::PolicyDims<kDModel, kHeads, kEncoderLayers, kDecoderLayers, kFfn0, kFfn1, kFfn2") !=
        std::string::npos);

  const std::string s = nao::test::readFile((out / "nao_model_weights.S").string());
  const std::string abs_copy = fs::absolute(out / "model.bin").lexically_normal().string();
  for (const std::string& line : {std::string(".section .rodata\n"), std::string(".balign 64\n"),
                                 std::string(".globl nao_model_blob\n"), std::string("nao_model_blob:\n"),
                                 ".incbin \"" + abs_copy + "\"\n", std::string("nao_model_blob_end:\n"),
                                 std::string(".section .note.GNU-stack,\"\",@progbits\n")})
    CHECK_MESSAGE(s.find(line) != std::string::npos, line);
}

TEST_CASE("a metadata longer than a constexpr strlen may count (a run latent's codes) is written with its length") {
  const fs::path dir = freshDir("codegen_long_metadata");
  const std::string model_path = (dir / "in.bin").string();
  const nao::PolicyArch arch = nao::smallArch();
  nao::ModelHeader h = makeHeader(arch);
  h.metadata_json = R"({"seed":11,"pad":")" + std::string(300000, 'x') + R"(\"q"})";
  nao::writeModelFile(model_path, h, nao::test::randomManifestTensors(arch, 5));
  nao::codegen::generate(model_path, (dir / "gen").string());
  const std::string config = nao::test::readFile((dir / "gen" / "nao_model_config.hpp").string());
  const std::string head = "inline constexpr std::string_view kMetadataJson{\"{\\\"seed\\\":11,";
  CHECK(config.find(head) != std::string::npos);
  // The length given is the metadata's (the escapes make the literal longer than that).
  CHECK(config.find("\\\"q\\\"}\", " + std::to_string(h.metadata_json.size()) + "};") != std::string::npos);
}

TEST_CASE("nao_codegen leaves unchanged outputs alone and rewrites what a new model changes") {
  const nao::PolicyArch arch = nao::smallArch();
  const SmallModel m = smallModel("codegen_rerun", 5);
  const std::string& model_path = m.path;
  const fs::path& out = m.out;
  nao::codegen::generate(model_path, out.string());
  const auto stamp = fs::last_write_time(out / "nao_model_config.hpp");

  const nao::codegen::Result again = nao::codegen::generate(model_path, out.string());
  CHECK(again.written.empty());
  CHECK(again.unchanged.size() == 6);
  CHECK(fs::last_write_time(out / "nao_model_config.hpp") == stamp);

  // Other weights, same architecture: the model copy, the checksum in the config and the .S
  // comment change; the dims header does not.
  nao::writeModelFile(model_path, makeHeader(arch), nao::test::randomManifestTensors(arch, 6));
  const nao::codegen::Result changed = nao::codegen::generate(model_path, out.string());
  CHECK(changed.written.size() == 3);
  REQUIRE(changed.unchanged.size() == 3);
  CHECK(fs::path(changed.unchanged[0]).filename() == "nao_model_dims.hpp");
  CHECK(fs::path(changed.unchanged[1]).filename() == "model.int8");    // still empty: fp32
  CHECK(fs::path(changed.unchanged[2]).filename() == "model.packed");  // likewise
}

namespace {

/// out/nao_model_weights.S .incbin's out/`file` (absolute path) between `symbol` and its _end.
void checkIncbinBetween(const fs::path& out, const std::string& file, const std::string& symbol) {
  const std::string s = nao::test::readFile((out / "nao_model_weights.S").string());
  const std::string abs_blob = fs::absolute(out / file).lexically_normal().string();
  const std::size_t start = s.find(symbol + ":\n"), incbin = s.find(".incbin \"" + abs_blob + "\"\n"),
                    end = s.find(symbol + "_end:\n");
  CHECK(start != std::string::npos);
  CHECK(incbin != std::string::npos);
  CHECK(end != std::string::npos);
  CHECK((start < incbin && incbin < end));
}

}  // namespace

TEST_CASE("nao_codegen --precision int8 compiles in the int8 blob beside the model, described by the config") {
  const nao::PolicyArch arch = nao::smallArch();
  const SmallModel m = smallModel("codegen_int8", 9);
  const std::string& model_path = m.path;
  const fs::path& out = m.out;
  nao::codegen::generate(model_path, out.string());
  // fp32 -> int8 over the same directory: the config, the .S and the blob change, nothing else.
  const nao::codegen::Result r = nao::codegen::generate(model_path, out.string(), nao::WeightPrecision::kInt8);
  CHECK(r.written.size() == 3);
  CHECK(r.unchanged.size() == 3);
  const nao::AlignedBytes want = nao::quantizeModelInt8(r.model);
  const std::string blob = nao::test::readFile((out / "model.int8").string());
  REQUIRE(blob.size() == want.size);
  CHECK(std::memcmp(blob.data(), want.data.get(), want.size) == 0);
  CHECK(blob.size() == nao::quantizedModelBytes(arch));

  const std::string config = nao::test::readFile((out / "nao_model_config.hpp").string());
  CHECK(config.find("inline constexpr bool kInt8Weights = true;") != std::string::npos);
  CHECK(config.find("inline constexpr std::size_t kInt8Bytes = " + std::to_string(want.size) + ";") !=
        std::string::npos);
  char checksum[64];
  std::snprintf(checksum, sizeof checksum, "kInt8Checksum = 0x%016llxull;",
                static_cast<unsigned long long>(nao::quantizedChecksum(want.data.get(), want.size)));
  CHECK(config.find(checksum) != std::string::npos);

  checkIncbinBetween(out, "model.int8", "nao_model_int8");
}

TEST_CASE("nao_codegen --precision fp32-packed compiles in the packed blob beside the model, described by the config") {
  const nao::PolicyArch arch = nao::smallArch();
  const SmallModel m = smallModel("codegen_packed", 10);
  const fs::path& out = m.out;
  nao::codegen::generate(m.path, out.string());
  // fp32 -> fp32-packed: the config, the .S and the packed blob change, nothing else.
  const nao::codegen::Result r = nao::codegen::generate(m.path, out.string(), nao::WeightPrecision::kFp32Packed);
  CHECK(r.written.size() == 3);
  CHECK(r.unchanged.size() == 3);
  const nao::AlignedBytes want = nao::packModelFp32(r.model);
  const std::string blob = nao::test::readFile((out / "model.packed").string());
  REQUIRE(blob.size() == want.size);
  CHECK(std::memcmp(blob.data(), want.data.get(), want.size) == 0);
  CHECK(blob.size() == nao::packedModelBytes(arch));
  CHECK(nao::test::readFile((out / "model.int8").string()).empty());

  const std::string config = nao::test::readFile((out / "nao_model_config.hpp").string());
  CHECK(config.find("inline constexpr bool kPackedWeights = true;") != std::string::npos);
  CHECK(config.find("inline constexpr bool kInt8Weights = false;") != std::string::npos);
  CHECK(config.find("inline constexpr std::size_t kPackedBytes = " + std::to_string(want.size) + ";") !=
        std::string::npos);
  char checksum[64];
  std::snprintf(checksum, sizeof checksum, "kPackedChecksum = 0x%016llxull;",
                static_cast<unsigned long long>(nao::quantizedChecksum(want.data.get(), want.size)));
  CHECK(config.find(checksum) != std::string::npos);

  checkIncbinBetween(out, "model.packed", "nao_model_packed");
}

TEST_CASE("nao_codegen refuses a bad model and writes nothing") {
  const fs::path dir = freshDir("codegen_bad");
  const std::string model_path = nao::test::writeTempFile("codegen_bad.bin", "NAOPOLCY not really a model at all........");
  const fs::path out = dir / "gen";
  CHECK_THROWS_AS(nao::codegen::generate(model_path, out.string()), nao::ModelFileError);
  CHECK_FALSE(fs::exists(out));
}

TEST_CASE("the dims header refuses an FFN depth nao::PolicyDims cannot express") {
  nao::PolicyArch arch = nao::smallArch();
  arch.ffn_hidden = {64, 64};
  const nao::ModelFile m =
      nao::decodeModel(nao::encodeModel(makeHeader(arch), nao::test::randomManifestTensors(arch, 1)), "two.bin");
  const std::string dims = nao::codegen::dimsHeader(m);
  CHECK(dims.find("#error \"nao::PolicyDims supports exactly 3 FFN hidden layers; this model has 2\"") != std::string::npos);
  CHECK(dims.find("using Dims") == std::string::npos);
}

TEST_CASE("archConstants is the one table of compile-time dimensions: the config states each, the Dims alias passes the marked ones in PolicyDims' order") {
  // The template arguments of the compiled dimensions, in PolicyDims' parameter order.
  const auto arguments = [](const nao::PolicyArch& a) {
    std::vector<int> v;
    for (const nao::codegen::ArchConstant& c : nao::codegen::archConstants(a))
      if (c.policy_dims_argument) v.push_back(c.value);
    return v;
  };
  // SmallPolicyDims = PolicyDims<32, 4, 2, 2, 64, 64, 64, 8> (nao/policy_weights.hpp): the table
  // sizes and the head (movements, key poses, steps, chunk) are runtime extents.
  CHECK(arguments(nao::smallArch()) == std::vector<int>{32, 4, 2, 2, 64, 64, 64, 8});
  CHECK(arguments(nao::paperArch()) == std::vector<int>{128, 4, 4, 4, 512, 512, 512, 20});
  CHECK(nao::SmallPolicyDims::arch() == nao::smallArch());
  CHECK(nao::PaperPolicyDims::arch() == nao::paperArch());

  nao::PolicyArch arch = nao::smallArch();
  arch.movements = 5;
  arch.clusters = 7;
  arch.window = 12;
  arch.max_steps = 100;
  nao::ModelHeader header = makeHeader(arch);
  header.movement_names = {"a", "b", "c", "d", "e"};
  const nao::ModelFile m =
      nao::decodeModel(nao::encodeModel(header, nao::test::randomManifestTensors(arch, 1)), "five.bin");
  const std::string config = nao::codegen::configHeader(m, "five.bin");
  const std::string dims = nao::codegen::dimsHeader(m);
  std::string expected_alias = "using Dims = nao::PolicyDims<";
  bool first = true;
  for (const nao::codegen::ArchConstant& c : nao::codegen::archConstants(arch)) {
    const std::string line = "inline constexpr int " + c.name + " = " + std::to_string(c.value) + ";";
    CHECK_MESSAGE(config.find(line) != std::string::npos, line);
    if (c.policy_dims_argument) {
      expected_alias += (first ? "" : ", ") + c.name;
      first = false;
    }
  }
  CHECK(config.find("inline constexpr int kMovements = 5;") != std::string::npos);
  CHECK(config.find("inline constexpr int kWindow = 12;") != std::string::npos);
  CHECK(dims.find(expected_alias + ">;") != std::string::npos);
}
