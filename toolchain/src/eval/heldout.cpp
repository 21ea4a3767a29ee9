// Held-out demonstrations of an evaluation (nao/tools/heldout.hpp).
#include "nao/tools/heldout.hpp"

#include "nao/tools/reference_source.hpp"

#include <nlohmann/json.hpp>

#include <charconv>
#include <cstdio>
#include <stdexcept>

namespace nao::tools {

ValidationSet validationDemos(const std::string& metadata_json, const std::string& movement,
                              const std::string& origin) {
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  const nlohmann::json* val = nullptr;
  if (j.is_object() && j.contains("split") && j["split"].is_object() && j["split"].contains("val") &&
      j["split"]["val"].is_array())
    val = &j["split"]["val"];
  if (val == nullptr)
    throw std::runtime_error(origin + ": the model's metadata names no validation demonstrations (split.val); "
                                      "the evaluation needs them to start and to score the rollouts");
  ValidationSet v;
  // The trainer records its own seed, not the synthesiser's; the data set of toolchain/nao
  // train is synthesised with seed 1. A future data.synth_seed is honoured.
  if (j.contains("data") && j["data"].is_object() && j["data"].contains("synth_seed") &&
      j["data"]["synth_seed"].is_number_unsigned()) {
    v.seed = j["data"]["synth_seed"].get<std::uint64_t>();
    v.seed_assumed = false;
  }
  for (const nlohmann::json& n : *val) {
    if (!n.is_string()) continue;
    const std::string name = n.get<std::string>();
    const auto cut = name.rfind('_');
    if (cut == std::string::npos || name.substr(0, cut) != movement) continue;
    const std::string digits = name.substr(cut + 1);
    int index = 0;
    const auto r = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    if (digits.empty() || r.ec != std::errc() || r.ptr != digits.data() + digits.size() || index < 0) continue;
    v.names.push_back(name);
    v.indices.push_back(index);
  }
  if (v.names.empty())
    throw std::runtime_error(origin + ": the model's metadata names no validation demonstration of movement '" +
                             movement + "' (split.val)");
  return v;
}

ValidationSet testDemos(const std::string& movement, std::uint64_t test_seed, int count) {
  if (count < 1) throw std::invalid_argument("a test set needs at least one demonstration");
  ValidationSet v;
  v.seed = kReferenceSeedBase + test_seed;
  v.seed_assumed = false;
  for (int i = 0; i < count; ++i) {
    char index[16];
    std::snprintf(index, sizeof index, "%03d", i);
    v.names.push_back(movement + "_test" + std::to_string(test_seed) + "_" + index);
    v.indices.push_back(i);
  }
  return v;
}

}  // namespace nao::tools
