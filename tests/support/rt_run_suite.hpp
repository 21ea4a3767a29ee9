// Helpers of the in-process nao_rt suites (test_rt_run, test_rt_run_codes): a per-process
// directory for their files, a random small-config model.bin, a run and its one-line error.
#pragma once

#include "rt_cli.hpp"
#include "rt_run.hpp"

#include "nao/model_file.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace nao::test::rt_suite {

using Dims = SmallPolicyDims;
namespace fs = std::filesystem;

// Per process: suites of several build trees may run at the same time.
inline fs::path suiteDir() {
  return fs::temp_directory_path() / "nao_rt_tests" / ("rt_run_" + std::to_string(::getpid()));
}

// Removes the suite's files when the suite ends.
struct RemoveSuiteDir {
  ~RemoveSuiteDir() {
    std::error_code ec;
    fs::remove_all(suiteDir(), ec);
  }
};
inline const RemoveSuiteDir remove_suite_dir;

inline fs::path tempDir(const std::string& name) {
  const fs::path dir = suiteDir() / name;
  fs::remove_all(dir);
  fs::create_directories(dir.parent_path());
  return dir;
}

/// A random small-config model.bin (movements elbow, whole_arm, wrist like the trainer's); `law_gain`
/// fills law.gain (the random policy's is 0).
inline std::string writeModel(const std::string& name, Conditioning c, const std::string& metadata = "{}",
                              const PolicyArch& arch = smallArch(), std::uint64_t seed = 7, float law_gain = 0.0f) {
  const ArmModel arm = loadArmModel(kUrdfPath);
  ModelHeader h;
  h.arch = arch;
  h.conditioning = c;
  h.joints = trainedJoints(arm);
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = metadata;
  const fs::path dir = suiteDir();
  fs::create_directories(dir);
  const std::string path = (dir / name).string();
  std::vector<std::vector<float>> tensors = makeRandomPolicy(arch, arm, seed).tensors;
  const std::vector<TensorSpec> manifest = policyManifest(arch);
  for (std::size_t i = 0; i < manifest.size(); ++i)
    if (manifest[i].name == "law.gain") std::fill(tensors[i].begin(), tensors[i].end(), law_gain);
  writeModelFile(path, h, tensors);
  return path;
}

struct Outcome {
  rt::RunReport report;
  std::string out, err;
};

/// runController of `o`, with `law` in place of the policy if given.
inline Outcome run(const rt::RunOptions& o, ActionLaw* law = nullptr) {
  std::ostringstream out, err;
  Outcome r;
  r.report = rt::runController<Dims>(o, out, err, nullptr, law);
  r.out = out.str();
  r.err = err.str();
  return r;
}

/// What runMain prints on failure: exactly one line.
inline std::string errorLine(const rt::RunOptions& o, int& status) {
  std::ostringstream out, err;
  status = rt::runMain<Dims>(o, out, err);
  return err.str();
}

inline bool oneLine(const std::string& s) { return !s.empty() && s.find('\n') == s.size() - 1; }

inline rt::RunOptions options(const std::string& weights, const std::string& reference, const fs::path& log = {}) {
  rt::RunOptions o;
  o.weights_path = weights;
  o.reference = reference;
  o.log_dir = log.string();
  return o;
}

inline std::string bytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace nao::test::rt_suite
