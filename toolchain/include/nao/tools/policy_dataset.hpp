// The policy's training data (docs/policy.md "Data"): a clustered data set (centroids.json +
// <movement>_<index>/features.csv from `nao_toolchain cluster`), the samples built from it,
// the seeded train/validation split by demonstration, the normalisation statistics of the
// training split, the zero-action and repeat-last-action baselines and the data fingerprint.
// Offline code without libtorch: allocates and may throw (UserError for bad input).
#pragma once

#include "nao/arm_model.hpp"

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace nao::tools {

/// One demonstration's feature-extracted trajectory on its 10 Hz grid (one entry per row of
/// features.csv).
struct PolicyDemo {
  std::string name;                    ///< "<movement>_<index>", the folder name
  int movement = 0;                    ///< index into PolicyData::movement_names (set by makePolicyData)
  std::vector<double> t_s;             ///< sample times, s (strictly increasing)
  std::vector<int> label;              ///< nearest centroid of each sample, 0..K-1
  std::vector<std::uint8_t> measured;  ///< 1: a human arm was measured at the sample, 0: held
  std::vector<JointVector> f;          ///< feature-extracted joint trajectory, rad
};

/// A whole data set in memory. Built by loadPolicyData or makePolicyData, which validate it.
struct PolicyData {
  std::vector<std::string> movement_names;          ///< sorted; index = movement index m
  std::vector<std::vector<JointVector>> centroids;  ///< [movement][cluster], rad; K per movement
  std::vector<PolicyDemo> demos;                    ///< sorted by name

  int movements() const { return static_cast<int>(movement_names.size()); }
  int clusters() const { return centroids.empty() ? 0 : static_cast<int>(centroids.front().size()); }
};

/// One training sample (docs/policy.md "Data"), rad.
struct PolicySample {
  JointVector q;       ///< q(t) = f(t)
  JointVector a_prev;  ///< a(t-1) = f(t) - f(t-1), 0 at t = 0
  JointVector r;       ///< r(t) = centroid label(t) of the demonstration's movement
  JointVector a;       ///< target a(t) = f(t+1) - f(t)
  int movement = 0;    ///< m
  int step = 0;        ///< s = t, clamped to max_steps - 1
  int demo = 0;        ///< index into PolicyData::demos
};

/// Per-joint normalisation statistics (population standard deviation, floored at kMinStd).
struct NormStats {
  JointVector q_mean, q_std;  ///< over q(t)
  JointVector a_mean, a_std;  ///< over the target actions a(t) (also used for a(t-1))
  JointVector r_mean, r_std;  ///< over r(t)
};
inline constexpr double kMinStd = 1e-6;  ///< rad

/// Demonstrations of the training and validation split (indices into PolicyData::demos,
/// ascending). No demonstration is in both.
struct PolicySplit {
  std::vector<int> train;
  std::vector<int> val;
};

/// MSE over samples and joints (rad^2) of two trivial predictors of a(t).
struct Baselines {
  double zero_action = 0.0;  ///< predict a(t) = 0
  double repeat_last = 0.0;  ///< predict a(t) = a(t-1)
};

/// Reads DIR/centroids.json and every DIR/<movement>_<index>/features.csv (columns t_s, label,
/// optional measured (missing: all 1), f_0..f_4), then makePolicyData. Throws UserError naming
/// the file (and line) for a missing or malformed directory, file or value.
PolicyData loadPolicyData(const std::string& dir);

/// Builds a data set from memory: the movements are the keys of `centroids` (sorted, so the
/// movement index is the position in name order), each demo's movement is the part of its name
/// before the last '_', demos are sorted by name. Throws UserError for inconsistent input:
/// unequal or zero K, a demo name that is not <movement>_<index> or names a movement without
/// centroids, a duplicate demo name, fewer than 2 samples, unequal column lengths,
/// non-increasing times, a label outside 0..K-1, a measured flag other than 0/1, a
/// non-finite value.
PolicyData makePolicyData(const std::map<std::string, std::vector<JointVector>>& centroids,
                          std::vector<PolicyDemo> demos);

/// The samples of demonstration `demo` (one per sample with a successor), steps clamped to
/// max_steps - 1.
std::vector<PolicySample> buildSamples(const PolicyData& data, int demo, int max_steps);

/// The samples of the listed demonstrations, concatenated in list order.
std::vector<PolicySample> buildSamples(const PolicyData& data, const std::vector<int>& demos, int max_steps);

/// Seeded split by demonstration: per movement, its demos (in name order) are shuffled
/// (Fisher-Yates with a local splitmix64 generator; one stream per movement derived from
/// `seed`), and the last round(val_fraction * n) become validation, at least 1 when n >= 2 and
/// val_fraction > 0, and at most n - 1. Throws UserError unless 0 <= val_fraction < 1.
PolicySplit splitByDemonstration(const PolicyData& data, double val_fraction, std::uint64_t seed);

/// 0..n-1 in a seeded random order (Fisher-Yates with a local splitmix64 generator): the same
/// on every platform and standard library.
std::vector<std::size_t> shuffledIndices(std::size_t n, std::uint64_t seed);

/// Normalisation statistics of `samples` (the training split's). Throws UserError if empty.
NormStats normStats(const std::vector<PolicySample>& samples);

/// Zero-action and repeat-last-action MSE over `samples` (0 for no samples), rad^2.
Baselines baselines(const std::vector<PolicySample>& samples);

/// FNV-1a 64 over the data set in a canonical little-endian byte form: movement names and
/// centroids, then per demo (name order) its name, movement, and per sample t_s, label,
/// measured, f (f64). Equal data give equal fingerprints on every platform.
std::uint64_t dataFingerprint(const PolicyData& data);

/// 16 lower-case hex digits.
std::string hex64(std::uint64_t value);

/// Names of the listed demonstrations.
std::vector<std::string> demoNames(const PolicyData& data, const std::vector<int>& demos);

}  // namespace nao::tools
