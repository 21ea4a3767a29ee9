// Hardware-in-the-loop substitute for the quality bar: the committed default model
// (models/default.bin, paper configuration) drives the simulated arm through nao_rt's whole
// loop — a recorded two-camera skeleton (file:), live retargeting, key-pose snap, policy, ODE
// servos — on held-out demonstrations (run seeds 1,000,000 + s, never used for training), beside the
// blend-law baseline under the same servos. The hand's RMSE against the toolchain's
// feature-extracted trajectory of the same demonstration is reported; no joint may ever leave
// its URDF limits (what is asserted: the test case).
#include "rt_run.hpp"
#include "nao/arm_model.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/baseline_laws.hpp"
#include "nao/tools/kmeans.hpp"
#include "support/reference_files.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
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
  const auto columns = test::readCsvColumns(ticks_csv);
  double worst = 0.0;
  rows = 0;
  for (int j = 0; j < kNumJoints; ++j) {
    const auto it = columns.find("q_" + std::to_string(j));
    REQUIRE(it != columns.end());
    rows = it->second.size();
    for (double q : it->second) worst = std::max({worst, arm.q_min[j] - q, q - arm.q_max[j]});
  }
  return worst;
}

// Fault counters by bit (controller.hpp).
constexpr std::size_t kNoHuman = 0, kLimited = 6, kBridged = 14;

// The one-tick inverse of the simulated first-order servo (sim_arm.hpp).
const double kServoInversionGain = servoStepGain(SimParams{});
static_assert(kNumControllerFaults == 16 && kFaultHumanBridged == 1u << kBridged, "fault bits renumbered: update the indices above");

}  // namespace

TEST_CASE("the default model imitates held-out demonstrations inside the limits within 3 mm RMS, better than the blend law and the servo-inversion gain law under the same servos") {
  // Baseline in the same run: the key-pose blend law the policy's labels follow,
  // driving the same servos. What it misses is the servo lag no policy of these labels removes.
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  for (const char* movement : {"whole_arm", "elbow", "wrist"}) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      // 0: the policy, 1: the blend law, 2: the first-order servo inversion (gain law).
      double rmse[3] = {0.0, 0.0, 0.0};
      for (int baseline = 0; baseline < 3; ++baseline) {
        rt::RunOptions o;
        o.weights_path = modelPath();
        o.reference = "file:" + test::syntheticReferenceCsv(movement, seed, runDir("references"));
        o.movement = movement;
        o.zero_timing = true;
        tools::BlendLaw blend(tools::KeyPoseBlend{}.pole);
        tools::GainLaw gain(kServoInversionGain);
        ActionLaw* const law[] = {nullptr, &blend, &gain};
        const char* const suffix[] = {"", "_law", "_gain"};
        const fs::path dir = runDir(std::string(movement) + "_" + std::to_string(seed) + suffix[baseline]);
        fs::remove_all(dir);
        fs::create_directories(dir.parent_path());
        o.log_dir = dir.string();
        std::ostringstream out, err;
        const rt::RunReport r = rt::runController<PaperPolicyDims>(o, out, err, nullptr, law[baseline]);
        REQUIRE_MESSAGE(r.status == 0, err.str());
        std::size_t rows = 0;
        const double excess = worstLimitExcess(dir / "ticks.csv", arm, rows);
        rmse[baseline] = r.ee_rmse_m;
        const char* const name[] = {" policy   ", " blend law", " gain law "};
        MESSAGE(std::string(movement) << " seed " << seed << std::string(name[baseline]) << ": " << r.ticks
                                      << " ticks, end-effector RMSE " << r.ee_rmse_m * 1000.0 << " mm, worst limit excess "
                                      << excess << " rad, faults no_human " << r.faults[kNoHuman] << ", human_bridged "
                                      << r.faults[kBridged] << ", command_limited " << r.faults[kLimited]);
        CHECK(rows == static_cast<std::size_t>(r.ticks));
        CHECK(r.ticks > 50);
        // The servo target is clamped to the limit; ODE's hinge angle read back at that target
        // can land 1e-14 rad past it in float rounding (measured 2.5e-14 on wrist seed 3, where the
        // policy holds RWristYaw on its limit). 1e-12 rad is far below any physical excess.
        CHECK(excess <= 1e-12);
      }
      // The policy learns the residual of the first-order servo inversion from
      // execution labels (docs/policy.md), and nao_rt retargets with the demonstration's
      // calibrated human scale (the target it tracks is the one it is scored against). Measured
      // on these 9 runs: 0.30-0.84 mm, the gain law 0.50-1.05 mm, the blend law 5.1-9.2 mm.
      // Held to 3 mm (and 1 cm) on every run, and to beating both laws
      // under the same servos: what the network adds beyond the closed form is measured here.
      CHECK_MESSAGE(rmse[0] < 3e-3, std::string(movement) << " seed " << seed << ": policy RMSE " << rmse[0] * 1e3
                                             << " mm (blend law " << rmse[1] * 1e3 << " mm, gain law "
                                             << rmse[2] * 1e3 << " mm)");
      CHECK_MESSAGE(rmse[0] <= rmse[1], std::string(movement) << " seed " << seed << ": policy RMSE " << rmse[0] * 1e3
                                                 << " mm, worse than the blend law's " << rmse[1] * 1e3 << " mm");
      CHECK_MESSAGE(rmse[0] < rmse[2], std::string(movement) << " seed " << seed << ": policy RMSE " << rmse[0] * 1e3
                                                << " mm, not below the first-order servo inversion's "
                                                << rmse[2] * 1e3 << " mm");
    }
  }
  std::error_code ec;
  fs::remove_all(runDir("").parent_path(), ec);
}
