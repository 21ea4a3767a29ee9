// nao_rt --info (runInfo): one JSON object for a good model, exactly one stderr line and exit
// status 1 for anything else.
#include "rt_info.hpp"

#include "nao/policy_kernels.hpp"
#include "nao/policy_weights.hpp"
#include "nao/quantize.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <random>
#include <sstream>

namespace {

namespace fs = std::filesystem;

nao::ModelHeader makeHeader() {
  nao::ModelHeader h;
  h.arch = nao::smallArch();
  h.joints = nao::trainedJoints(nao::loadArmModel(nao::test::kUrdfPath));
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = R"({"seed":3,"epochs":2})";
  return h;
}

std::vector<std::vector<float>> randomTensors(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<std::vector<float>> out;
  for (const nao::TensorSpec& t : nao::policyManifest(nao::smallArch())) {
    std::vector<float> v(t.count());
    for (float& x : v) x = u(rng);
    out.push_back(std::move(v));
  }
  return out;
}

std::string modelPath(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / "rt_info";
  fs::create_directories(dir);
  return (dir / name).string();
}

struct Run {
  int status;
  std::string out, err;
};

Run info(const nao::rt::InfoOptions& options) {
  std::ostringstream out, err;
  const int status = nao::rt::runInfo(options, out, err);
  return {status, out.str(), err.str()};
}

nao::rt::InfoOptions withWeights(const std::string& path) {
  nao::rt::InfoOptions o;
  o.weights_path = path;
  o.urdf_path = nao::test::kUrdfPath;
  return o;
}

/// Exactly one line: text ending in the only newline.
bool oneLine(const std::string& s) { return !s.empty() && s.find('\n') == s.size() - 1; }

}  // namespace

TEST_CASE("nao_rt --info --weights prints one JSON object describing the model") {
  const std::string path = modelPath("good.bin");
  const std::uint64_t checksum = nao::writeModelFile(path, makeHeader(), randomTensors(1));
  const Run r = info(withWeights(path));
  CHECK(r.status == 0);
  CHECK(r.err.empty());
  const nlohmann::json j = nlohmann::json::parse(r.out);
  CHECK(j["format_version"] == 3);
  CHECK(j["d_model"] == 32);
  CHECK(j["heads"] == 4);
  CHECK(j["encoder_layers"] == 2);
  CHECK(j["decoder_layers"] == 2);
  CHECK(j["ffn_hidden"] == nlohmann::json::array({64, 64, 64}));
  CHECK(j["tokens"] == 5);
  CHECK(j["conditioning"] == "reference");
  CHECK(j["clusters"] == 10);
  CHECK(j["movements"] == nlohmann::json::array({"elbow", "whole_arm", "wrist"}));
  CHECK(j["parameters"] == nao::parameterCount(nao::smallArch()));
  CHECK(j["tensors"] == nao::policyManifest(nao::smallArch()).size());
  CHECK(j["max_steps"] == 256);
  CHECK(j["window"] == 8);  // the small architecture's
  char hex[32];
  std::snprintf(hex, sizeof hex, "0x%016llx", static_cast<unsigned long long>(checksum));
  CHECK(j["checksum"] == hex);
  REQUIRE(j["joints"].size() == 5);
  const nao::ArmModel arm = nao::loadArmModel(nao::test::kUrdfPath);
  CHECK(j["joints"][3]["name"] == "RElbowRoll");
  CHECK(j["joints"][3]["lower"].get<double>() == arm.q_min[3]);
  CHECK(j["joints"][3]["velocity"].get<double>() == arm.v_max[3]);
  CHECK(j["metadata"]["seed"] == 3);
  CHECK(j["source"] == path);
  CHECK(j["weights"] == "file");
  CHECK(j["precision"] == "fp32");
  CHECK(j["kernel"] == nao::policyKernelName(nao::bestPolicyKernel()));  // the binders' default
  CHECK(j["starts"] == nlohmann::json::parse(R"({"elbow":[],"whole_arm":[],"wrist":[]})"));  // none in this model
  CHECK(j["run_codes"] == nlohmann::json::parse(R"({"elbow":0,"whole_arm":0,"wrist":0})"));
  nao::rt::InfoOptions o8 = withWeights(path);
  o8.precision = "int8";
  CHECK(nlohmann::json::parse(info(o8).out)["precision"] == "int8");
  CHECK_FALSE(j.contains("runs"));  // no compiled dimensions given: not known
  // "runs": whether the nao_rt's compiled dimensions compute this model's step.
  nao::rt::InfoOptions paper_only = withWeights(path);
  paper_only.computes = [](const nao::PolicyArch& a) { return nao::computesPolicyArch<nao::PaperPolicyDims>(a); };
  CHECK(nlohmann::json::parse(info(paper_only).out)["runs"] == false);
  nao::rt::InfoOptions both = withWeights(path);
  both.computes = [](const nao::PolicyArch& a) {
    return nao::computesPolicyArch<nao::PaperPolicyDims>(a) || nao::computesPolicyArch<nao::SmallPolicyDims>(a);
  };
  nlohmann::json jb = nlohmann::json::parse(info(both).out);
  CHECK(jb["runs"] == true);
  jb.erase("runs");
  CHECK(jb == j);  // the rest of the description is the same
}

TEST_CASE("nao_rt --info describes the compiled-in model, and says when there is none") {
  const std::vector<std::uint8_t> bytes = nao::encodeModel(makeHeader(), randomTensors(2));
  nao::rt::InfoOptions o;
  o.urdf_path = nao::test::kUrdfPath;
  Run r = info(o);
  CHECK(r.status == 1);
  CHECK(r.out.empty());
  CHECK(r.err == "nao_rt: no model is compiled into this build; pass --weights FILE\n");

  // As nao_rt's main hands it over: the bytes in place, the header and offsets as constants.
  const nao::ModelFile decoded = nao::decodeModel(bytes, "test");
  std::vector<std::uint64_t> offsets;
  std::vector<nao::TensorExtent> extents;
  for (const nao::TensorEntry& t : decoded.tensors) {
    offsets.push_back(t.offset);
    extents.push_back(nao::viewExtent(t.spec));
  }
  o.compiled = {bytes.data(), bytes.size(), decoded.checksum, &decoded.header, offsets.data(), extents.data(),
                offsets.size()};
  r = info(o);
  CHECK(r.status == 0);
  CHECK(nlohmann::json::parse(r.out)["source"] == "compiled-in");
  CHECK(nlohmann::json::parse(r.out)["weights"] == "compiled");
  CHECK(nlohmann::json::parse(r.out)["precision"] == "fp32");
  // Generated with nao_codegen --precision int8: a run defaults to int8, and --info says so.
  const nao::AlignedBytes blob = nao::quantizeModelInt8(decoded);
  o.compiled.int8_bytes = blob.data.get();
  o.compiled.int8_size = blob.size;
  o.compiled.int8_checksum = nao::quantizedChecksum(blob.data.get(), blob.size);
  CHECK(nlohmann::json::parse(info(o).out)["precision"] == "int8");
  o.precision = "fp32";
  CHECK(nlohmann::json::parse(info(o).out)["precision"] == "fp32");
  // Generated with --precision fp32-packed: a run defaults to fp32-packed.
  o.precision.clear();
  o.compiled.int8_bytes = nullptr;
  const nao::AlignedBytes packed = nao::packModelFp32(decoded);
  o.compiled.packed_bytes = packed.data.get();
  o.compiled.packed_size = packed.size;
  o.compiled.packed_checksum = nao::quantizedChecksum(packed.data.get(), packed.size);
  CHECK(nlohmann::json::parse(info(o).out)["precision"] == "fp32-packed");
}

TEST_CASE("nao_rt --info fails with exactly one stderr line on a bad model, joints or URDF") {
  const std::string good = modelPath("good2.bin");
  nao::writeModelFile(good, makeHeader(), randomTensors(1));

  SUBCASE("a damaged file") {
    std::string bytes = nao::test::readFile(good);
    bytes[bytes.size() / 2] ^= 0x55;
    const std::string path = nao::test::writeTempFile("rt_info_damaged.bin", bytes);
    const Run r = info(withWeights(path));
    CHECK(r.status == 1);
    CHECK(r.out.empty());
    CHECK(oneLine(r.err));
    CHECK(r.err.rfind("nao_rt: " + path + ": checksum mismatch (stored 0x", 0) == 0);
  }
  SUBCASE("a missing file") {
    const Run r = info(withWeights(modelPath("does_not_exist.bin")));
    CHECK(r.status == 1);
    CHECK(oneLine(r.err));
    CHECK(r.err.find("does_not_exist.bin: cannot open") != std::string::npos);
  }
  SUBCASE("not a model") {
    const std::string path = nao::test::writeTempFile("rt_info_text.bin", "hello, world\n");
    const Run r = info(withWeights(path));
    CHECK(r.err == "nao_rt: " + path + ": not a nao-rt model (bad magic)\n");
  }
  SUBCASE("joints that differ from the URDF") {
    nao::ModelHeader h = makeHeader();
    h.joints[0].upper += 1e-3;
    const std::string path = modelPath("other_limits.bin");
    nao::writeModelFile(path, h, randomTensors(1));
    const Run r = info(withWeights(path));
    CHECK(r.status == 1);
    CHECK(oneLine(r.err));
    CHECK(r.err.find("joint 'RShoulderPitch' upper limit") != std::string::npos);
    CHECK(r.err.find(nao::test::kUrdfPath) != std::string::npos);
  }
  SUBCASE("an unusable URDF") {
    nao::rt::InfoOptions o = withWeights(good);
    o.urdf_path = modelPath("no_such.urdf");
    const Run r = info(o);
    CHECK(r.status == 1);
    CHECK(oneLine(r.err));
  }
}

TEST_CASE("nao_rt --info shows metadata that is not JSON as a string") {
  nao::ModelHeader h = makeHeader();
  h.metadata_json = "trained by hand \xff";
  const std::string path = modelPath("text_meta.bin");
  nao::writeModelFile(path, h, randomTensors(1));
  const Run r = info(withWeights(path));
  REQUIRE(r.status == 0);
  CHECK(nlohmann::json::parse(r.out)["metadata"].is_string());
}

TEST_CASE("nao_rt --info lists the autonomous starts per movement (name, ticks), and refuses unusable ones in one line") {
  nao::ModelHeader h = makeHeader();
  nao::ModelStart a, b;
  a.name = "elbow_003";
  a.ticks = 117;
  a.q << 1.2, -0.3, 1.0, 0.6, 0.1;
  b.name = "wrist_002";
  b.ticks = 98;
  h.metadata_json = nao::withModelStarts(h.metadata_json, h.movement_names, {{a}, {}, {b}});
  const std::string path = modelPath("with_starts.bin");
  nao::writeModelFile(path, h, randomTensors(1));
  const Run r = info(withWeights(path));
  REQUIRE(r.status == 0);
  const nlohmann::json j = nlohmann::json::parse(r.out);
  CHECK(j["starts"] == nlohmann::json::parse(
                           R"({"elbow":[{"name":"elbow_003","ticks":117}],"whole_arm":[],"wrist":[{"name":"wrist_002","ticks":98}]})"));
  CHECK(j["metadata"]["starts"]["elbow"][0]["q"][0] == 1.2);

  // Run codes are counted per movement, and their table is left out of the printed metadata.
  std::vector<nao::ModelRunCodes> codes(3);
  for (nao::ModelRunCodes& c : codes) c.d = h.arch.d_model;
  codes[1].names = {"whole_arm_000", "whole_arm_004"};
  codes[1].q.assign(2, nao::JointVector::Zero());
  codes[1].code.assign(2 * static_cast<std::size_t>(h.arch.d_model), 0.5f);
  codes[1].dtw_m = {0.0, 0.01, 0.01, 0.0};
  nao::ModelHeader hc = h;
  hc.metadata_json = nao::withModelRunCodes(h.metadata_json, h.movement_names, codes);
  const std::string coded = modelPath("with_codes.bin");
  nao::writeModelFile(coded, hc, randomTensors(1));
  const Run rc = info(withWeights(coded));
  REQUIRE(rc.status == 0);
  const nlohmann::json jc = nlohmann::json::parse(rc.out);
  CHECK(jc["run_codes"] == nlohmann::json::parse(R"({"elbow":0,"whole_arm":2,"wrist":0})"));
  CHECK_FALSE(jc["metadata"].contains("run_codes"));
  CHECK(jc["metadata"]["starts"] == j["metadata"]["starts"]);

  h.metadata_json = R"({"starts":{"elbow":[{"name":"x","ticks":5}],"whole_arm":[],"wrist":[]}})";
  const std::string bad = modelPath("bad_starts.bin");
  nao::writeModelFile(bad, h, randomTensors(1));
  const Run rb = info(withWeights(bad));
  CHECK(rb.status == 1);
  CHECK(oneLine(rb.err));
  CHECK(rb.err.find("has no q") != std::string::npos);
}
