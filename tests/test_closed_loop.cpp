// Hardware-in-the-loop substitute for issue 5's quality bar: the committed default model
// (models/default.bin, paper configuration) drives the simulated arm through nao_rt's whole
// loop — synthetic two-camera keypoints, live retargeting, key-pose snap, policy, ODE servos —
// on held-out demonstrations (run seeds 1,000,000 + s, never used for training). The hand must
// stay within 1 cm RMS of the toolchain's feature-extracted trajectory of the same
// demonstration, and no joint may ever leave its URDF limits.
#include "rt_run.hpp"
#include "nao/arm_model.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace nao;

namespace {

namespace fs = std::filesystem;

std::string modelPath() {
  return (fs::path(NAO_TEST_DATA_DIR).parent_path().parent_path() / "models" / "default.bin").string();
}

fs::path runDir(const std::string& name) {
  return fs::temp_directory_path() / "nao_rt_tests" / ("closed_loop_" + std::to_string(::getpid())) / name;
}

// Largest amount by which any q_j of ticks.csv lies outside [q_min_j, q_max_j] (0: never).
double worstLimitExcess(const fs::path& ticks_csv, const ArmModel& arm, std::size_t& rows) {
  std::ifstream in(ticks_csv);
  std::string line;
  REQUIRE(std::getline(in, line));
  std::vector<std::string> header;
  {
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, ',');) header.push_back(cell);
  }
  std::vector<std::size_t> col(kNumJoints);
  for (int j = 0; j < kNumJoints; ++j) {
    const auto it = std::find(header.begin(), header.end(), "q_" + std::to_string(j));
    REQUIRE(it != header.end());
    col[static_cast<std::size_t>(j)] = static_cast<std::size_t>(it - header.begin());
  }
  double worst = 0.0;
  rows = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, ',');) cells.push_back(cell);
    for (int j = 0; j < kNumJoints; ++j) {
      const double q = std::stod(cells.at(col[static_cast<std::size_t>(j)]));
      worst = std::max({worst, arm.q_min[j] - q, q - arm.q_max[j]});
    }
    ++rows;
  }
  return worst;
}

}  // namespace

TEST_CASE("the default model imitates held-out demonstrations of every movement within 1 cm RMS, inside the limits") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  for (const char* movement : {"whole_arm", "elbow", "wrist"}) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      rt::RunOptions o;
      o.weights_path = modelPath();
      o.reference = std::string("synthetic:") + movement;
      o.seed = seed;
      o.zero_timing = true;
      const fs::path dir = runDir(std::string(movement) + "_" + std::to_string(seed));
      fs::remove_all(dir);
      fs::create_directories(dir.parent_path());
      o.log_dir = dir.string();
      std::ostringstream out, err;
      const rt::RunReport r = rt::runController<PaperPolicyDims>(o, out, err);
      REQUIRE_MESSAGE(r.status == 0, err.str());
      std::size_t rows = 0;
      const double excess = worstLimitExcess(dir / "ticks.csv", arm, rows);
      MESSAGE(std::string(movement) << " seed " << seed << ": " << r.ticks << " ticks, end-effector RMSE "
                       << r.ee_rmse_m * 1000.0 << " mm, worst limit excess " << excess << " rad, faults no_human "
                       << r.faults[0] << ", human_bridged " << r.faults[8] << ", command_limited " << r.faults[6]);
      CHECK(rows == static_cast<std::size_t>(r.ticks));
      CHECK(r.ticks > 50);
      CHECK(r.ee_rmse_m < 0.01);
      CHECK(excess <= 0.0);
    }
  }
  std::error_code ec;
  fs::remove_all(runDir("").parent_path(), ec);
}
