// model.bin: the byte layout round-trips, equal inputs give equal bytes, and every way a
// file can be wrong is rejected with a message that names the file and the problem.
#include "nao/model_file.hpp"

#include "support/model_spec.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>

namespace {

using nao::ModelFileError;

const std::string kOrigin = "x.bin";

nao::ModelHeader makeHeader(const nao::PolicyArch& arch) {
  nao::ModelHeader h;
  h.arch = arch;
  h.conditioning = nao::Conditioning::kReference;
  h.joints = nao::trainedJoints(nao::loadArmModel(nao::test::kUrdfPath));
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = R"({"seed":7,"epochs":3,"final_loss":0.125,"note":"caf\u00e9"})";
  return h;
}

std::vector<std::uint8_t> smallModelBytes() {
  return nao::encodeModel(makeHeader(nao::smallArch()), nao::test::randomManifestTensors(nao::smallArch(), 1));
}

std::uint32_t getU32(const std::vector<std::uint8_t>& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= std::uint32_t{b[at + i]} << (8 * i);
  return v;
}

void putU32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::uint64_t getU64(const std::vector<std::uint8_t>& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= std::uint64_t{b[at + i]} << (8 * i);
  return v;
}

void putU64(std::vector<std::uint8_t>& b, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

/// Re-seals a deliberately edited file so that the check under test, not the checksum, fires.
void reseal(std::vector<std::uint8_t>& b) { putU64(b, b.size() - 8, nao::fnv1a64(b.data(), b.size() - 8)); }

// Table entry layout (docs/policy.md): char[64] name, u32 rank, u32 dims[4], u64 offset, u64 count.
constexpr std::size_t kEntryBytes = 100;
std::size_t headerSize(const std::vector<std::uint8_t>& b) { return getU32(b, 12); }
std::size_t entryAt(const std::vector<std::uint8_t>& b, std::size_t index, std::size_t n_tensors) {
  return headerSize(b) - kEntryBytes * (n_tensors - index);
}

std::string decodeError(std::vector<std::uint8_t> bytes) {
  try {
    nao::decodeModel(std::move(bytes), kOrigin);
  } catch (const ModelFileError& e) {
    return e.what();
  }
  return "(accepted)";
}

std::size_t indexOf(const std::vector<nao::TensorSpec>& m, const std::string& name) {
  for (std::size_t i = 0; i < m.size(); ++i)
    if (m[i].name == name) return i;
  FAIL("no tensor " << name);
  return 0;
}

}  // namespace

TEST_CASE("model.bin round trip: decode(encode(x)) gives the header, the tensors and the checksum back") {
  const nao::PolicyArch arch = nao::smallArch();
  const nao::ModelHeader header = makeHeader(arch);
  const auto tensors = nao::test::randomManifestTensors(arch, 1);
  const std::vector<std::uint8_t> bytes = nao::encodeModel(header, tensors);

  const nao::ModelFile m = nao::decodeModel(bytes, kOrigin);
  CHECK(m.header.arch == arch);
  CHECK(m.header.conditioning == header.conditioning);
  REQUIRE(m.header.joints.size() == header.joints.size());
  for (std::size_t j = 0; j < header.joints.size(); ++j) {
    CHECK(m.header.joints[j].name == header.joints[j].name);
    CHECK(m.header.joints[j].lower == header.joints[j].lower);
    CHECK(m.header.joints[j].upper == header.joints[j].upper);
    CHECK(m.header.joints[j].velocity == header.joints[j].velocity);
  }
  CHECK(m.header.movement_names == header.movement_names);
  CHECK(m.header.metadata_json == header.metadata_json);
  CHECK(m.bytes == bytes);
  CHECK(m.checksum == getU64(bytes, bytes.size() - 8));
  CHECK(m.checksum == nao::fnv1a64(bytes.data(), bytes.size() - 8));

  const auto manifest = nao::policyManifest(arch);
  REQUIRE(m.tensors.size() == manifest.size());
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    INFO("tensor " << manifest[i].name);
    CHECK(m.tensors[i].spec.name == manifest[i].name);
    CHECK(m.tensors[i].spec.shape == manifest[i].shape);
    CHECK(m.tensors[i].offset % nao::kModelAlignment == 0);
    CHECK(m.find(manifest[i].name) == i);
    CHECK(std::memcmp(m.data(i), tensors[i].data(), tensors[i].size() * sizeof(float)) == 0);
  }
  CHECK_THROWS_AS(m.find("no.such.tensor"), ModelFileError);
}

TEST_CASE("model.bin is little-endian with the documented fixed header") {
  const auto b = smallModelBytes();
  CHECK(std::memcmp(b.data(), "NAOPOLCY", 8) == 0);
  CHECK(getU32(b, 8) == 3);
  const nao::PolicyArch a = nao::smallArch();
  // ..., max_steps, window, chunk, bins (always 0), conditioning
  const std::uint32_t fields[14] = {32, 4, 2, 2, 3, 5, 3, 3, 10, 256, 8, 1, 0, 0};
  for (int i = 0; i < 14; ++i) CHECK(getU32(b, 16 + 4 * static_cast<std::size_t>(i)) == fields[i]);
  CHECK(getU32(b, 72) == static_cast<std::uint32_t>(a.ffn_hidden[0]));
  // The first joint name follows the three FFN widths.
  CHECK(std::string(reinterpret_cast<const char*>(b.data() + 84)) == "RShoulderPitch");
  // Tensor table: entry 0 is embed.in.weight [3,32] at the first 64-byte boundary after the header.
  const std::size_t n = nao::policyManifest(a).size();
  const std::size_t e0 = entryAt(b, 0, n);
  CHECK(std::string(reinterpret_cast<const char*>(b.data() + e0)) == "embed.in.weight");
  CHECK(getU32(b, e0 + 64) == 2);
  CHECK(getU32(b, e0 + 68) == 3);
  CHECK(getU32(b, e0 + 72) == 32);
  CHECK(getU32(b, e0 + 76) == 0);
  CHECK(getU64(b, e0 + 84) == (headerSize(b) + 63) / 64 * 64);
  CHECK(getU64(b, e0 + 92) == 96);
  CHECK(getU32(b, entryAt(b, 0, n) - 4) == n);
}

TEST_CASE("two encodes of the same input are byte-identical") {
  CHECK(smallModelBytes() == smallModelBytes());
  // and a different seed gives different bytes (the test would pass vacuously otherwise)
  CHECK(nao::encodeModel(makeHeader(nao::smallArch()), nao::test::randomManifestTensors(nao::smallArch(), 2)) != smallModelBytes());
}

TEST_CASE("writeModelFile writes the encoded bytes in one rename; readModelFile reads them back") {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests" / "model_file";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "model.bin").string();
  const nao::ModelHeader header = makeHeader(nao::smallArch());
  const auto tensors = nao::test::randomManifestTensors(nao::smallArch(), 1);

  const std::uint64_t checksum = nao::writeModelFile(path, header, tensors);
  const nao::ModelFile m = nao::readModelFile(path);
  CHECK(m.checksum == checksum);
  CHECK(m.bytes == nao::encodeModel(header, tensors));
  // Overwriting an existing file works and leaves no temporary file behind.
  CHECK(nao::writeModelFile(path, header, tensors) == checksum);
  std::size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    INFO(entry.path().string());
    CHECK(entry.path().filename() == "model.bin");
    ++files;
  }
  CHECK(files == 1);

  try {
    nao::readModelFile((dir / "missing.bin").string());
    FAIL("a missing file was accepted");
  } catch (const ModelFileError& e) {
    CHECK(std::string(e.what()).rfind((dir / "missing.bin").string() + ": cannot open", 0) == 0);
  }
  try {
    nao::writeModelFile((dir / "no" / "such" / "dir.bin").string(), header, tensors);
    FAIL("writing into a missing directory succeeded");
  } catch (const ModelFileError& e) {
    CHECK(std::string(e.what()).find("dir.bin: cannot create a temporary file") != std::string::npos);
  }
}

TEST_CASE("decodeModel rejects a file that is not a model, or of another format version") {
  auto b = smallModelBytes();
  b[3] ^= 0x20;
  CHECK(decodeError(b) == "x.bin: not a nao-rt model (bad magic)");
  CHECK(decodeError({'P', 'K', 3, 4}) == "x.bin: not a nao-rt model (bad magic)");

  b = smallModelBytes();
  putU32(b, 8, 7);
  reseal(b);
  CHECK(decodeError(b) == "x.bin: format version 7 is not supported (this build reads 3)");
}

TEST_CASE("decodeModel reports a file cut short, in the header or in the data, as truncated") {
  const auto full = smallModelBytes();
  const std::size_t hs = headerSize(full);
  const std::size_t n = full.size();
  const std::size_t bias_at = nao::decodeModel(full, kOrigin).tensors[1].offset;  // embed.in.bias
  REQUIRE(hs > 300);
  struct Cut {
    std::size_t length;
    const char* expect;
  };
  const Cut cuts[] = {
      {0, "x.bin: truncated (0 bytes, header needs at least 72)"},
      {5, "x.bin: truncated (5 bytes, header needs at least 72)"},
      {10, "x.bin: truncated (10 bytes, header needs at least 72)"},
      {20, "x.bin: truncated (20 bytes, header needs at least 72)"},
      {40, "x.bin: truncated (40 bytes, header needs "},
      {61, "x.bin: truncated (61 bytes, header needs "},
      {300, "x.bin: truncated (300 bytes, header needs "},
      {hs - 1, "x.bin: truncated ("},
      {hs, "x.bin: truncated: tensor 'embed.in.weight' ends at byte"},
      {hs + 8, "x.bin: truncated: tensor 'embed.in.weight' ends at byte"},
      {bias_at + 16, "x.bin: truncated: tensor 'embed.in.bias' ends at byte"},
      {n / 2, "x.bin: truncated: tensor '"},
      {n - 9, "x.bin: truncated: tensor 'centroids' ends at byte"},
      {n - 8, "x.bin: truncated: tensor 'centroids' ends at byte"},
      {n - 1, "x.bin: truncated: tensor 'centroids' ends at byte"},
  };
  for (const Cut& c : cuts) {
    INFO("cut at " << c.length << " of " << n << " bytes (header " << hs << ")");
    const std::string msg = decodeError(std::vector<std::uint8_t>(full.begin(), full.begin() + static_cast<long>(c.length)));
    CHECK_MESSAGE(msg.rfind(c.expect, 0) == 0, msg);
  }
  const std::string at_header = decodeError(std::vector<std::uint8_t>(full.begin(), full.begin() + 300));
  CHECK(at_header == "x.bin: truncated (300 bytes, header needs " + std::to_string(hs) + ")");
}

TEST_CASE("decodeModel reports any flipped byte after the version as a checksum mismatch") {
  const auto full = smallModelBytes();
  const std::size_t hs = headerSize(full);
  const std::size_t n_tensors = nao::policyManifest(nao::smallArch()).size();
  const std::size_t table = entryAt(full, 0, n_tensors);
  // Every byte after the version up to the tensor table (sizes, architecture, joints,
  // movements, metadata), the first two and the last table entries whole, every 7th byte of
  // the rest of the table, a sample of the data, and the checksum itself.
  std::vector<std::size_t> positions;
  for (std::size_t p = 12; p < table + 2 * kEntryBytes; ++p) positions.push_back(p);
  for (std::size_t p = table + 2 * kEntryBytes; p < hs - kEntryBytes; p += 7) positions.push_back(p);
  for (std::size_t p = hs - kEntryBytes; p < hs; ++p) positions.push_back(p);
  for (std::size_t p = hs; p < full.size() - 8; p += 997) positions.push_back(p);
  for (std::size_t p = full.size() - 8; p < full.size(); ++p) positions.push_back(p);
  const std::uint8_t masks[] = {0x01, 0x80, 0xff, 0x10, 0x7f};
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const std::size_t p = positions[i];
    const std::uint8_t mask = masks[i % 5];
    auto b = full;
    b[p] ^= mask;
    const std::string msg = decodeError(std::move(b));
    if (msg.rfind("x.bin: checksum mismatch (stored 0x", 0) != 0)
      FAIL_CHECK("byte " << p << " ^ " << int{mask} << ": " << msg);
  }
  auto b = full;
  b[hs + 5] ^= 0x10;
  const std::string msg = decodeError(b);
  CHECK(msg.find("computed 0x") != std::string::npos);
  CHECK(msg.size() == std::string("x.bin: checksum mismatch (stored 0x0123456789abcdef, computed 0x0123456789abcdef)").size());
}

TEST_CASE("decodeModel rejects a tensor table that differs from the manifest of its architecture") {
  const nao::PolicyArch arch = nao::smallArch();
  const auto manifest = nao::policyManifest(arch);
  const std::size_t n = manifest.size();
  const auto full = smallModelBytes();

  SUBCASE("a shape that is not the manifest's") {
    auto b = full;
    const std::size_t e = entryAt(b, indexOf(manifest, "embed.joint_enc"), n);
    putU32(b, e + 72, 64);   // dims[1]: d_model 32 -> 64
    putU64(b, e + 92, 320);  // and a matching element count
    reseal(b);
    CHECK(decodeError(b) == "x.bin: tensor 2 is 'embed.joint_enc' [5,64], the manifest expects 'embed.joint_enc' [5,32]");

    b = full;
    putU32(b, e + 64, 3);  // rank 3: [5,32,0]
    reseal(b);
    CHECK(decodeError(b) == "x.bin: tensor 2 is 'embed.joint_enc' [5,32,0], the manifest expects 'embed.joint_enc' [5,32]");
  }
  SUBCASE("two tensors swapped") {
    auto b = full;
    const std::size_t q = indexOf(manifest, "enc.1.attn.wq"), k = indexOf(manifest, "enc.1.attn.wk");
    for (std::size_t i = 0; i < 64; ++i) std::swap(b[entryAt(b, q, n) + i], b[entryAt(b, k, n) + i]);
    reseal(b);
    CHECK(decodeError(b) == "x.bin: tensor " + std::to_string(q) +
                                " is 'enc.1.attn.wk' [32,32], the manifest expects 'enc.1.attn.wq' [32,32] (out of "
                                "order: the manifest has 'enc.1.attn.wk' at position " +
                                std::to_string(k) + ")");
  }
  SUBCASE("a name not in the manifest") {
    auto b = full;
    const std::size_t e = entryAt(b, indexOf(manifest, "head.bias"), n);
    b[e + 5] = 'B';
    reseal(b);
    CHECK(decodeError(b).find("is 'head.Bias' [1], the manifest expects 'head.bias' [1] (no such tensor in the manifest)") !=
          std::string::npos);
  }
  SUBCASE("an offset that is not the canonical one") {
    auto b = full;
    const std::size_t i = indexOf(manifest, "dec.0.cross.wv");
    const std::size_t e = entryAt(b, i, n);
    putU64(b, e + 84, getU64(b, e + 84) + 64);
    reseal(b);
    CHECK(decodeError(b).rfind("x.bin: tensor " + std::to_string(i) + " 'dec.0.cross.wv' starts at byte ", 0) == 0);
  }
  SUBCASE("an element count that is not the shape's") {
    auto b = full;
    const std::size_t e = entryAt(b, 0, n);
    putU64(b, e + 92, 95);
    reseal(b);
    CHECK(decodeError(b) == "x.bin: tensor 0 'embed.in.weight' says 95 elements, its shape [3,32] holds 96");
  }
  SUBCASE("bytes between the last tensor and the checksum") {
    auto b = full;
    b.insert(b.end() - 8, 8, 0);
    reseal(b);
    CHECK(decodeError(b).find("8 unexpected bytes between the last tensor") != std::string::npos);
  }
}

TEST_CASE("decodeModel rejects a NaN or Inf weight, naming the tensor and the element") {
  const auto manifest = nao::policyManifest(nao::smallArch());
  const nao::ModelFile good = nao::decodeModel(smallModelBytes(), kOrigin);
  auto poison = [&](const std::string& name, std::size_t element, float value) {
    auto b = good.bytes;
    const std::size_t at = good.tensors[good.find(name)].offset + 4 * element;
    std::uint32_t bits;
    std::memcpy(&bits, &value, 4);
    putU32(b, at, bits);
    reseal(b);
    return decodeError(b);
  };
  CHECK(poison("dec.1.cross.wv", 17, std::numeric_limits<float>::quiet_NaN()) ==
        "x.bin: tensor 'dec.1.cross.wv' holds NaN/Inf at element 17 (NaN)");
  CHECK(poison("embed.step", 0, std::numeric_limits<float>::infinity()) ==
        "x.bin: tensor 'embed.step' holds NaN/Inf at element 0 (+Inf)");
  CHECK(poison("centroids", 149, -std::numeric_limits<float>::infinity()) ==
        "x.bin: tensor 'centroids' holds NaN/Inf at element 149 (-Inf)");
}

TEST_CASE("decodeModel rejects an unusable architecture, and encodeModel refuses to write one") {
  auto b = smallModelBytes();
  putU32(b, 16, 30);  // d_model 30 with 4 heads
  reseal(b);
  CHECK(decodeError(b) == "x.bin: architecture: d_model 30 is not a multiple of heads 4");

  b = smallModelBytes();
  putU32(b, 68, 2);  // conditioning
  reseal(b);
  CHECK(decodeError(b) == "x.bin: header: conditioning 2 is neither 0 (reference) nor 1 (autonomous)");

  // The format's bins field: an action-bins head is not something this runtime runs.
  b = smallModelBytes();
  putU32(b, 64, 8);
  reseal(b);
  CHECK(decodeError(b) ==
        "x.bin: header: the model has an action-bins head (bins 8); this runtime runs the regression head only (bins 0)");

  nao::PolicyArch bad = nao::smallArch();
  bad.d_model = 30;
  CHECK_THROWS_WITH_AS(nao::encodeModel(makeHeader(bad), nao::test::randomManifestTensors(bad, 1)),
                       "cannot encode model: architecture: d_model 30 is not a multiple of heads 4", ModelFileError);
}

TEST_CASE("encodeModel refuses tensors that do not fit the manifest, and non-finite weights") {
  const nao::PolicyArch arch = nao::smallArch();
  const nao::ModelHeader header = makeHeader(arch);
  auto tensors = nao::test::randomManifestTensors(arch, 1);
  auto fewer = tensors;
  fewer.pop_back();
  CHECK_THROWS_AS(nao::encodeModel(header, fewer), ModelFileError);
  auto wrong = tensors;
  wrong[2].push_back(0.0f);
  CHECK_THROWS_WITH_AS(nao::encodeModel(header, wrong),
                       "cannot encode model: tensor 2 'embed.joint_enc' [5,32] needs 160 floats, got 161", ModelFileError);
  auto nan = tensors;
  nan[5][0] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_AS(nao::encodeModel(header, nan), ModelFileError);
  nao::ModelHeader no_movements = header;
  no_movements.movement_names.pop_back();
  CHECK_THROWS_AS(nao::encodeModel(no_movements, tensors), ModelFileError);
  nao::ModelHeader long_name = header;
  long_name.movement_names[0] = std::string(32, 'x');
  CHECK_THROWS_AS(nao::encodeModel(long_name, tensors), ModelFileError);
}

TEST_CASE("checkJointsMatch accepts the URDF's joints and names the joint that differs") {
  const nao::ArmModel arm = nao::loadArmModel(nao::test::kUrdfPath);
  const nao::PolicyArch arch = nao::smallArch();
  const auto tensors = nao::test::randomManifestTensors(arch, 1);
  auto check = [&](const nao::ModelHeader& h) -> std::string {
    const nao::ModelFile m = nao::decodeModel(nao::encodeModel(h, tensors), kOrigin);
    try {
      nao::checkJointsMatch(m, arm, kOrigin);
    } catch (const ModelFileError& e) {
      return e.what();
    }
    return "(accepted)";
  };
  nao::ModelHeader h = makeHeader(arch);
  CHECK(check(h) == "(accepted)");

  // Within 1e-9 is the same limit.
  h.joints[2].upper += 5e-10;
  CHECK(check(h) == "(accepted)");

  h = makeHeader(arch);
  h.joints[1].name = "LShoulderRoll";
  CHECK(check(h) == "x.bin: joint 1 is 'LShoulderRoll' in the model, 'RShoulderRoll' in the URDF");

  h = makeHeader(arch);
  h.joints[3].lower += 1e-3;
  const std::string msg = check(h);
  CHECK(msg.rfind("x.bin: joint 'RElbowRoll' lower limit is ", 0) == 0);
  char model_value[64], urdf_value[64];
  std::snprintf(model_value, sizeof model_value, "%.15g", arm.q_min[3] + 1e-3);
  std::snprintf(urdf_value, sizeof urdf_value, "%.15g", arm.q_min[3]);
  CHECK(msg.find(std::string(model_value) + " rad in the model") != std::string::npos);
  CHECK(msg.find(std::string(urdf_value) + " rad in the URDF") != std::string::npos);

  h = makeHeader(arch);
  h.joints[4].velocity *= 2.0;
  CHECK(check(h).rfind("x.bin: joint 'RWristYaw' velocity limit is ", 0) == 0);
}

TEST_CASE("trainedJoints lists the arm's joints in order with their limits") {
  const nao::ArmModel arm = nao::loadArmModel(nao::test::kUrdfPath);
  const auto joints = nao::trainedJoints(arm);
  REQUIRE(joints.size() == static_cast<std::size_t>(nao::kNumJoints));
  for (int j = 0; j < nao::kNumJoints; ++j) {
    const auto& t = joints[static_cast<std::size_t>(j)];
    CHECK(t.name == nao::kJointNames[static_cast<std::size_t>(j)]);
    CHECK(t.lower == arm.q_min[j]);
    CHECK(t.upper == arm.q_max[j]);
    CHECK(t.velocity == arm.v_max[j]);
  }
}

TEST_CASE("the paper manifest's parameter count equals a hand count from docs/policy.md") {
  // d = 128, J = 5 tokens, F = 3 features, M = 3 movements, K = 10 clusters, S = 256 steps,
  // FFN d-512-512-512-d.
  const std::size_t d = 128, J = 5, F = 3, M = 3, K = 10, S = 256, h = 512, H = 4, W = 20;
  const std::size_t embed = F * d + d     // embed.in
                            + J * d       // embed.joint_enc
                            + M * d       // embed.movement
                            + S * d       // embed.step
                            + d + d       // embed.act
                            + J * d;      // embed.joint_dec
  const std::size_t ln = 2 * d;
  const std::size_t attn = 4 * (d * d + d);
  const std::size_t age_bias = H * W;  // temporal attention only: encoder self, decoder cross
  const std::size_t ffn = (d * h + h) + (h * h + h) + (h * h + h) + (h * d + d);
  const std::size_t enc_layer = 2 * ln + attn + age_bias + ffn;
  const std::size_t dec_layer = 3 * ln + 2 * attn + age_bias + ffn;
  const std::size_t total = embed + 4 * enc_layer + ln + 4 * dec_layer + ln  //
                            + (d + 1)                                        // head
                            + J                                              // law.gain
                            + 6 * J                                          // norm.{q,a,r}_{mean,std}
                            + M * K * J;                                     // centroids
  // The same sum with the numbers written out.
  CHECK(embed == 35200);
  CHECK(ffn == 657024);
  CHECK(enc_layer == 723664);
  CHECK(dec_layer == 789968);
  CHECK(total == 6090554);
  CHECK(nao::parameterCount(nao::paperArch()) == total);
  // 8 embeddings, 21 tensors per encoder layer, 31 per decoder layer, 2 norms, head 2, law 1, norm 6,
  // centroids.
  CHECK(nao::policyManifest(nao::paperArch()).size() == 8 + 4 * 21 + 2 + 4 * 31 + 2 + 2 + 1 + 6 + 1);
}

TEST_CASE("a paper-size model round-trips") {
  const nao::PolicyArch arch = nao::paperArch();
  const auto tensors = nao::test::randomManifestTensors(arch, 3);
  const auto bytes = nao::encodeModel(makeHeader(arch), tensors);
  CHECK(bytes.size() > 24'000'000);
  const nao::ModelFile m = nao::decodeModel(bytes, kOrigin);
  CHECK(m.header.arch == arch);
  const std::size_t last = m.tensors.size() - 1;
  CHECK(std::memcmp(m.data(last), tensors[last].data(), tensors[last].size() * 4) == 0);
}

TEST_CASE("an empty file, unordered joint limits and non-positive velocity limits are refused") {
  // memcmp on the null data() of an empty vector was undefined behaviour.
  CHECK(decodeError({}) == "x.bin: truncated (0 bytes, header needs at least 72)");

  // Joint j's lower/upper/velocity doubles follow the 64 fixed bytes, the FFN widths and the
  // 56-byte records of the joints before it (docs/policy.md).
  const std::vector<std::uint8_t> good = smallModelBytes();
  const std::size_t joints = 72 + 4 * nao::smallArch().ffn_hidden.size();
  auto withJoint = [&](int j, int field, double v) {
    std::vector<std::uint8_t> b = good;
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    putU64(b, joints + 56 * static_cast<std::size_t>(j) + 32 + 8 * static_cast<std::size_t>(field), bits);
    reseal(b);
    return b;
  };
  CHECK(decodeError(withJoint(2, 0, 0.0)) == "(accepted)");  // the offsets point at the limits
  CHECK(decodeError(withJoint(2, 0, 3.0)) ==
        "x.bin: header: joint 'RElbowYaw' has lower limit 3 rad not below its upper limit 2.08567 rad");
  CHECK(decodeError(withJoint(4, 2, 0.0)) == "x.bin: header: joint 'RWristYaw' has velocity limit 0 rad/s, expected > 0");
  CHECK(decodeError(withJoint(0, 2, -1.0)) ==
        "x.bin: header: joint 'RShoulderPitch' has velocity limit -1 rad/s, expected > 0");

  // Metadata nested deeper than any JSON the trainer writes: nao_rt --info dumps it recursively.
  nao::ModelHeader deep = makeHeader(nao::smallArch());
  deep.metadata_json = std::string(100000, '[') + std::string(100000, ']');
  CHECK_THROWS_WITH_AS(nao::encodeModel(deep, nao::test::randomManifestTensors(nao::smallArch(), 1)),
                       doctest::Contains("metadata nests deeper than 64 levels"), ModelFileError);

  deep.metadata_json = std::string(200, 'x');
  std::vector<std::uint8_t> b = nao::encodeModel(deep, nao::test::randomManifestTensors(nao::smallArch(), 1));
  const std::string marker(200, 'x');
  const auto at = std::search(b.begin(), b.end(), marker.begin(), marker.end());
  REQUIRE(at != b.end());
  std::fill(at, at + 100, static_cast<std::uint8_t>('['));
  std::fill(at + 100, at + 200, static_cast<std::uint8_t>(']'));
  reseal(b);
  CHECK(decodeError(b) == "x.bin: header: metadata nests deeper than 64 levels (at byte 64)");

  // The writer refuses what the reader would.
  nao::ModelHeader h = makeHeader(nao::smallArch());
  h.joints[1].upper = h.joints[1].lower;
  CHECK_THROWS_WITH_AS(nao::encodeModel(h, nao::test::randomManifestTensors(nao::smallArch(), 1)),
                       doctest::Contains("joint 'RShoulderRoll' has lower limit"), ModelFileError);
}

TEST_CASE("autonomous starts round-trip through the metadata: one list per movement, other keys kept in place") {
  const std::vector<std::string> movements = {"elbow", "whole_arm", "wrist"};
  nao::ModelStarts starts(3);
  nao::ModelStart a;
  a.name = "elbow_003";
  a.ticks = 117;
  a.q << 1.25, -0.3, 1.0 / 3.0, 0.6, -1e-17;  // not short decimals: the JSON must keep every bit
  nao::ModelStart b = a;
  b.name = "elbow_010";
  b.ticks = 1;
  b.q *= -0.5;
  starts[0] = {a, b};
  starts[2] = {a};
  const std::string meta = R"({"format":"nao-rt policy metadata 1","split":{"val":["elbow_003"]},"z":1})";
  const std::string with = nao::withModelStarts(meta, movements, starts);
  // Keys before stay where they were; "starts" is added at the end, movements in order.
  CHECK(with.rfind(R"({"format":"nao-rt policy metadata 1","split":{"val":["elbow_003"]},"z":1,"starts":{"elbow":)", 0) == 0);
  CHECK(with.find(R"("whole_arm":[])") != std::string::npos);
  const nao::ModelStarts back = nao::test::specOf(with, movements, 128, kOrigin).starts;
  REQUIRE(back.size() == 3);
  REQUIRE(back[0].size() == 2);
  CHECK(back[0][0].name == "elbow_003");
  CHECK(back[0][0].ticks == 117);
  CHECK(back[0][0].q == a.q);  // bit for bit
  CHECK(back[0][1].q == b.q);
  CHECK(back[1].empty());
  REQUIRE(back[2].size() == 1);
  CHECK(back[2][0].name == "elbow_003");
  // Replacing them again gives the same text (a second model-starts run changes nothing).
  CHECK(nao::withModelStarts(with, movements, starts) == with);
  // No key: no starts, one empty list per movement.
  const nao::ModelStarts none = nao::test::specOf(meta, movements, 128, kOrigin).starts;
  CHECK(none.size() == 3);
  CHECK(std::all_of(none.begin(), none.end(), [](const auto& l) { return l.empty(); }));
  CHECK(nao::test::specOf("not json", movements, 128, kOrigin).starts.size() == 3);
}

TEST_CASE("unusable autonomous starts are refused with the origin and what is wrong") {
  const std::vector<std::string> movements = {"elbow", "whole_arm", "wrist"};
  const std::string ok_entry = R"({"name":"e_1","ticks":5,"q":[0,0,0,0,0]})";
  const auto meta = [&](const std::string& elbow, const std::string& extra = "") {
    return R"({"starts":{"elbow":)" + elbow + R"(,"whole_arm":[],"wrist":[])" + extra + "}}";
  };
  CHECK(nao::test::specOf(meta("[" + ok_entry + "]"), movements, 128, kOrigin).starts[0].size() == 1);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"starts":[1]})", "not an object"},
      {R"({"starts":{"elbow":[],"whole_arm":[]}})", "no entry for movement 'wrist'"},
      {meta("[]", R"(,"wave":[])"), "'wave'"},
      {meta("{}"), "not a list"},
      {meta("[1]"), "not an object"},
      {meta(R"([{"ticks":5,"q":[0,0,0,0,0]}])"), "no name"},
      {meta(R"([{"name":"","ticks":5,"q":[0,0,0,0,0]}])"), "no name"},
      {meta(R"([{"name":"e","ticks":0,"q":[0,0,0,0,0]}])"), "no ticks"},
      {meta(R"([{"name":"e","ticks":36001,"q":[0,0,0,0,0]}])"), "no ticks"},
      {meta(R"([{"name":"e","ticks":2.5,"q":[0,0,0,0,0]}])"), "no ticks"},
      {meta(R"([{"name":"e","ticks":5,"q":[0,0,0,0]}])"), "no q"},
      {meta(R"([{"name":"e","ticks":5,"q":[0,0,"x",0,0]}])"), "not finite numbers"},
  };
  for (const auto& [text, says] : bad) {
    CAPTURE(text);
    CHECK_THROWS_WITH_AS(nao::test::specOf(text, movements, 128, kOrigin).starts, doctest::Contains(says.c_str()), ModelFileError);
    CHECK_THROWS_WITH_AS(nao::test::specOf(text, movements, 128, kOrigin).starts, doctest::Contains("x.bin: metadata \"starts\""),
                         ModelFileError);
  }
  nao::ModelStarts wrong(2);
  CHECK_THROWS_AS(nao::withModelStarts("{}", movements, wrong), ModelFileError);
  CHECK_THROWS_AS(nao::withModelStarts("[1]", movements, nao::ModelStarts(3)), ModelFileError);
}

TEST_CASE("an autonomous model's workspace round-trips through its metadata; a malformed one is refused naming the movement") {
  const std::vector<std::string> movements = {"elbow", "wave"};
  std::vector<nao::ModelWorkspace> w(2);
  w[0].lo << -1.0, -0.5, 0.1, 0.2, -1.5;
  w[0].hi << 1.0, 0.3, 1.1, 1.2, 1.5;
  w[1].lo = w[0].lo * 0.5;
  w[1].hi = w[0].hi * 0.5 + nao::JointVector::Constant(0.125);
  const std::string with = nao::withModelWorkspace(R"({"seed":3})", movements, w);
  const std::vector<nao::ModelWorkspace> back = nao::test::specOf(with, movements, 128, "m.bin").workspace;
  REQUIRE(back.size() == 2);
  for (std::size_t m = 0; m < 2; ++m) {
    CHECK(back[m].lo == w[m].lo);  // exact: the doubles are written round-trip
    CHECK(back[m].hi == w[m].hi);
  }
  CHECK(nao::test::specOf(R"({"seed":3})", movements, 128, "m.bin").workspace.empty());  // older models: none
  CHECK_THROWS_WITH_AS(nao::test::specOf(nao::withModelWorkspace("{}", movements, {w[1], w[0]}), {"elbow"}, 128, "m.bin").workspace,
                       doctest::Contains("'wave', which is not a movement"), ModelFileError);
  std::vector<nao::ModelWorkspace> bad = w;
  bad[1].lo[3] = bad[1].hi[3] + 0.5;
  CHECK_THROWS_WITH_AS(nao::test::specOf(nao::withModelWorkspace("{}", movements, bad), movements, 128, "m.bin").workspace,
                       doctest::Contains("'wave' has lo above hi"), ModelFileError);
  CHECK_THROWS_AS(nao::withModelWorkspace("{}", movements, {w[0]}), ModelFileError);
}

TEST_CASE("run codes round-trip through the metadata bit for bit; malformed ones are refused naming what is wrong") {
  const std::vector<std::string> movements = {"elbow", "wave"};
  std::vector<nao::ModelRunCodes> codes(2);
  for (std::size_t m = 0; m < 2; ++m) {
    nao::ModelRunCodes& c = codes[m];
    c.d = 4;
    for (int i = 0; i < 3 - static_cast<int>(m); ++i) {
      c.names.push_back(movements[m] + "_" + std::to_string(i));
      c.q.push_back(nao::JointVector::Constant(1.0 / (3.0 + i)));
      for (int k = 0; k < c.d; ++k) c.code.push_back(static_cast<float>(k - i) / 7.0f);
    }
    const std::size_t n = c.size();
    c.dtw_m.assign(n * n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t k = i + 1; k < n; ++k) c.dtw_m[i * n + k] = c.dtw_m[k * n + i] = 0.01 / static_cast<double>(i + k + 3);
  }
  const std::string with = nao::withModelRunCodes(R"({"seed":3})", movements, codes);
  const std::vector<nao::ModelRunCodes> back = nao::test::specOf(with, movements, 4, "m.bin").run_codes;
  REQUIRE(back.size() == 2);
  for (std::size_t m = 0; m < 2; ++m) {
    CHECK(back[m].names == codes[m].names);
    CHECK(back[m].q == codes[m].q);
    CHECK(back[m].code == codes[m].code);
    CHECK(back[m].dtw_m == codes[m].dtw_m);
    CHECK(back[m].d == 4);
  }
  CHECK(nao::test::specOf(R"({"seed":3})", movements, 4, "m.bin").run_codes.empty());  // no run latent: none
  CHECK_THROWS_WITH_AS(nao::test::specOf(with, movements, 8, "m.bin").run_codes, doctest::Contains("code (d_model 8)"), ModelFileError);
  CHECK_THROWS_WITH_AS(nao::test::specOf(with, {"elbow"}, 4, "m.bin").run_codes, doctest::Contains("'wave', which is not a movement"),
                       ModelFileError);
  CHECK_THROWS_WITH_AS(nao::test::specOf(with, {"elbow", "wave", "wrist"}, 4, "m.bin").run_codes,
                       doctest::Contains("no entry for movement 'wrist'"), ModelFileError);
  std::vector<nao::ModelRunCodes> bad = codes;
  bad[0].dtw_m[1] += 1e-3;  // no longer symmetric
  CHECK_THROWS_WITH_AS(nao::test::specOf(nao::withModelRunCodes("{}", movements, bad), movements, 4, "m.bin").run_codes,
                       doctest::Contains("not symmetric"), ModelFileError);
  bad = codes;
  bad[1].q[0][2] = std::nan("");
  CHECK_THROWS_WITH_AS(nao::test::specOf(nao::withModelRunCodes("{}", movements, bad), movements, 4, "m.bin").run_codes,
                       doctest::Contains("'wave' entry 0's q"), ModelFileError);
  bad = codes;
  bad[0].code.pop_back();
  CHECK_THROWS_AS(nao::withModelRunCodes("{}", movements, bad), ModelFileError);
  CHECK_THROWS_AS(nao::withModelRunCodes("{}", movements, {codes[0]}), ModelFileError);
}

TEST_CASE("readModelSpec: the movement names, the split and the data fingerprint, each as recorded or empty") {
  const std::vector<std::string> movements{"elbow", "wave"};
  const nao::ModelSpec spec = nao::test::specOf(
      R"({"split": {"train": ["elbow_000", "wave_001", 7], "val": ["elbow_002"]}, "data": {"fingerprint": "871bd180d467f00e"}})",
      movements, 4, "m.bin");
  CHECK(spec.movement_names == movements);
  CHECK(spec.split.train == std::vector<std::string>{"elbow_000", "wave_001"});  // what is not a name is left out
  CHECK(spec.split.val == std::vector<std::string>{"elbow_002"});
  CHECK(spec.data_fingerprint == "871bd180d467f00e");
  const nao::ModelSpec none = nao::test::specOf(R"({"split": [1], "data": {"fingerprint": 3}})", movements, 4, "m.bin");
  CHECK(none.split.train.empty());
  CHECK(none.split.val.empty());
  CHECK(none.data_fingerprint.empty());
  CHECK(nao::test::specOf("", movements, 4, "m.bin").split.train.empty());
}
