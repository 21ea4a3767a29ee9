// Writes the model.bin seeds of tests/fuzz/corpus/model_file/ with the project's own writer
// (encodeModel): a tiny architecture of each conditioning (a few KB, where the trained models
// are 24 MB), and the damaged files the reader must refuse. Run: nao_fuzz_model_seeds DIR.
#include "nao/file_io.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/model_file.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace {

nao::PolicyArch tinyArch() {
  nao::PolicyArch a;
  a.d_model = 4;
  a.heads = 1;
  a.encoder_layers = 1;
  a.decoder_layers = 1;
  a.ffn_hidden = {4};
  a.movements = 1;
  a.clusters = 2;
  a.max_steps = 2;
  a.window = 2;
  return a;
}

std::vector<std::uint8_t> tinyModel(nao::Conditioning conditioning, const std::string& metadata =
    R"({"seed":1,"split":{"val":["elbow_000"]},"data":{"retarget":{"priority":"hand"}}})") {
  nao::ModelHeader h;
  h.arch = tinyArch();
  h.conditioning = conditioning;
  h.joints = nao::trainedJoints(nao::loadArmModel(NAO_DEFAULT_URDF));
  h.movement_names = {"elbow"};
  h.metadata_json = metadata;
  std::mt19937_64 rng(1);
  std::vector<std::vector<float>> tensors;
  for (const nao::TensorSpec& t : nao::policyManifest(h.arch)) {
    std::vector<float> v(t.count());
    for (float& x : v) x = static_cast<float>(static_cast<double>(rng() >> 11) * 0x1.0p-53 - 0.5);
    tensors.push_back(std::move(v));
  }
  return nao::encodeModel(h, tensors);
}

void reseal(std::vector<std::uint8_t>& b) {
  const std::uint64_t sum = nao::fnv1a64(b.data(), b.size() - 8);
  for (int i = 0; i < 8; ++i) b[b.size() - 8 + i] = static_cast<std::uint8_t>(sum >> (8 * i));
}

// Metadata nested 500 deep (the writer refuses it, so it is written flat and bracketed after).
std::vector<std::uint8_t> deepMetadata() {
  const std::string flat(1000, 'x');
  std::vector<std::uint8_t> b = tinyModel(nao::Conditioning::kReference, flat);
  const auto at = std::search(b.begin(), b.end(), flat.begin(), flat.end());
  std::fill(at, at + 500, static_cast<std::uint8_t>('['));
  std::fill(at + 500, at + 1000, static_cast<std::uint8_t>(']'));
  reseal(b);
  return b;
}

// Joint j's lower/upper/velocity doubles sit after the fixed fields, the FFN widths and j
// earlier joints (docs/policy.md); the checksum is redone so the reader gets past it.
std::vector<std::uint8_t> withJointValue(std::vector<std::uint8_t> b, int joint, int field, double v) {
  const std::size_t at = 72 + 4 * tinyArch().ffn_hidden.size() + 56 * static_cast<std::size_t>(joint) + 32 + 8 * field;
  std::memcpy(b.data() + at, &v, sizeof v);
  reseal(b);
  return b;
}

bool write(const std::string& dir, const char* name, const std::vector<std::uint8_t>& b) {
  const std::string problem = nao::writeFileAtomically(dir + "/" + name, b.data(), b.size());
  if (!problem.empty()) std::fprintf(stderr, "nao_fuzz_model_seeds: %s/%s: %s\n", dir.c_str(), name, problem.c_str());
  return problem.empty();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: nao_fuzz_model_seeds DIR\n");
    return 2;
  }
  const std::string dir = argv[1];
  const std::vector<std::uint8_t> reference = tinyModel(nao::Conditioning::kReference);
  const std::vector<std::uint8_t> autonomous = tinyModel(nao::Conditioning::kAutonomous);
  bool ok = write(dir, "tiny_reference.bin", reference) && write(dir, "tiny_autonomous.bin", autonomous);
  ok = ok && write(dir, "truncated_header.bin", {reference.begin(), reference.begin() + 100});
  ok = ok && write(dir, "empty.bin", {});
  ok = ok && write(dir, "lower_above_upper.bin", withJointValue(reference, 2, 0, 3.0));
  ok = ok && write(dir, "velocity_zero.bin", withJointValue(reference, 4, 2, 0.0));
  ok = ok && write(dir, "velocity_negative.bin", withJointValue(reference, 0, 2, -1.0));
  ok = ok && write(dir, "crash_deep_metadata.bin", deepMetadata());
  return ok ? 0 : 1;
}
