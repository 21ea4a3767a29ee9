// Fuzz target: a demonstration's features.csv, read the way training reads it (loadPolicyData
// on a scratch data set: a fixed centroids.json with K = 3 and the input as
// elbow_000/features.csv). Either a validated data set or UserError.
#include "fuzz_util.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"

#include <cmath>

namespace {

const std::string& dataDir() {
  static const std::string dir = [] {
    const char centroids[] =
        R"({"movements": {"elbow": {"centroids": [[0, 0, 0, 0.5, 0], [0.1, -0.2, 0.3, 0.4, 0.5], [-0.5, 0, 1, 1, 0]]}}})";
    return std::filesystem::path(nao::fuzz::writeScratch("data/centroids.json",
                                                         reinterpret_cast<const std::uint8_t*>(centroids),
                                                         sizeof centroids - 1))
        .parent_path()
        .string();
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& dir = dataDir();
  nao::fuzz::writeScratch("data/elbow_000/features.csv", data, size);
  try {
    const nao::tools::PolicyData d = nao::tools::loadPolicyData(dir);
    NAO_FUZZ_CHECK(d.demos.size() == 1 && d.clusters() == 3);
    const nao::tools::PolicyDemo& demo = d.demos.front();
    NAO_FUZZ_CHECK(demo.f.size() >= 2 && demo.t_s.size() == demo.f.size() && demo.label.size() == demo.f.size());
    for (std::size_t t = 0; t < demo.f.size(); ++t) {
      NAO_FUZZ_CHECK(std::isfinite(demo.t_s[t]) && demo.f[t].allFinite());
      NAO_FUZZ_CHECK(demo.label[t] >= 0 && demo.label[t] < 3);
    }
  } catch (const nao::tools::UserError&) {
  }
  return 0;
}
