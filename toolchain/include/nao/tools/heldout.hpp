// The held-out demonstrations an evaluation scores autonomous rollouts against (docs/evaluate.md):
// the model's validation demonstrations (metadata split.val), or a test set of the synthesiser
// that training never saw. Regenerated with the synthesiser (evaluate.hpp: regenerateTargets):
// offline code, allocates, throws.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

/// The demonstrations of one movement to regenerate with the synthesiser.
struct ValidationSet {
  std::uint64_t seed = 1;      ///< synthesiser run seed of the data set
  bool seed_assumed = true;    ///< the metadata does not say it: the training set's seed 1 assumed
  std::vector<std::string> names;  ///< e.g. "elbow_003"
  std::vector<int> indices;        ///< demonstration index within the movement
};

/// Reads split.val (and data.synth_seed when present) from a model's metadata JSON and keeps the
/// demonstrations of `movement`. Throws std::runtime_error naming `origin` when there are none.
ValidationSet validationDemos(const std::string& metadata_json, const std::string& movement, const std::string& origin);

/// A test set of `movement`: demonstrations 0 .. count-1 of run seed kReferenceSeedBase +
/// test_seed (never a training seed), named <movement>_test<seed>_<index>. Throws
/// std::invalid_argument if count < 1.
ValidationSet testDemos(const std::string& movement, std::uint64_t test_seed, int count);

}  // namespace nao::tools
