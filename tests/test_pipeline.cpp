// The offline front half end to end on the synthesiser's data: synth -> OpenPose files ->
// triangulation -> human kinematics -> retargeting, checked against the synthesiser's truth.
#include "nao/human_kinematics.hpp"
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/triangulate.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <filesystem>

using namespace nao;
using namespace nao::tools;

namespace {

namespace fs = std::filesystem;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// 3D errors (m) of every body point the triangulation kept, against the truth of the same frame.
std::vector<double> triangulationErrors(const SynthDemo& demo, const Skeleton& measured, int& n_kept, int& n_total) {
  std::vector<double> err;
  REQUIRE(measured.size() == demo.truth.size());
  for (std::size_t f = 0; f < measured.size(); ++f)
    for (int i = 0; i < kNumBody25; ++i) {
      if (!demo.truth[f].ok[i]) continue;
      ++n_total;
      if (!measured[f].ok[i]) continue;
      ++n_kept;
      err.push_back((measured[f].p_W[i] - demo.truth[f].p_W[i]).norm());
    }
  return err;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace

TEST_CASE("triangulating noise-free synthetic views reproduces the ground-truth keypoints within 0.5 mm") {
  const fs::path root = freshDir("pipeline_noise_free");
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    const SynthDemo demo = generateDemo(m, 0, 5, /*noise_free=*/true);
    writeDemo(demo, root.string());
    TriangulateOptions options;
    options.rate_hz = options.fps;  // keep every capture frame, to compare with truth.csv
    const Skeleton measured = triangulateDemo((root / demo.name).string(), options);
    int kept = 0, total = 0;
    const std::vector<double> err = triangulationErrors(demo, measured, kept, total);
    REQUIRE(!err.empty());
    const double worst = *std::max_element(err.begin(), err.end());
    CAPTURE(demo.name);
    CHECK_MESSAGE(worst < 0.5e-3, "largest error " << worst * 1e3 << " mm");
    // Noise-free views lose only points that leave an image: nearly everything is kept.
    CHECK_MESSAGE(kept >= 0.97 * total, kept << " of " << total << " points kept");

    // The human angles from the triangulated skeleton match the model's own joint values.
    HumanKinematicsConfig config;
    HumanArmData human;
    resetHumanArm(human);
    double worst_deg = 0.0;
    int n_measured = 0;
    for (std::size_t f = 0; f < measured.size(); ++f) {
      humanArmKinematics(config, human, measured[f]);
      if (!human.valid || !human.hand_seen || (human.flags & ~kHumanInvalidMask) != 0) continue;
      ++n_measured;
      worst_deg = std::max(worst_deg, (human.q - demo.q[f]).cwiseAbs().maxCoeff() / nao::test::kDeg);
    }
    CHECK_MESSAGE(n_measured >= 0.9 * static_cast<double>(measured.size()), n_measured << " frames measured");
    CHECK_MESSAGE(worst_deg < 0.5, "largest angle error from triangulated noise-free views: " << worst_deg << " deg");
  }
}

TEST_CASE("with the synthesiser's pixel noise the median triangulation error stays below 16 mm") {
  // The bound from the synthesiser's own ranges (docs/synth.md): pixel sd <= 2.5 px at
  // <= 3.4 m with f >= 1050 px is <= 8.1 mm across each camera's view; rays 50-70 deg apart make
  // that <= 13.5 mm in depth and ~6 mm across, a 3D RMS of <= 16 mm, and a Gaussian 3D error's
  // median is below its RMS.
  const fs::path root = freshDir("pipeline_noisy");
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    const SynthDemo demo = generateDemo(m, 1, 5, /*noise_free=*/false);
    writeDemo(demo, root.string());
    TriangulateOptions options;
    options.rate_hz = options.fps;
    const Skeleton measured = triangulateDemo((root / demo.name).string(), options);
    int kept = 0, total = 0;
    const std::vector<double> err = triangulationErrors(demo, measured, kept, total);
    CAPTURE(demo.name);
    MESSAGE(demo.name << ": median error " << median(err) * 1e3 << " mm, " << kept << "/" << total << " points kept");
    CHECK(median(err) < 16e-3);
    // Dropouts are 0.5-2 % per camera and point: a point is lost when either camera drops it.
    CHECK_MESSAGE(kept >= 0.9 * total, kept << " of " << total << " points kept");
  }
}

TEST_CASE("a retarget CSV reads back what was written") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const SynthDemo demo = generateDemo(Movement::kElbow, 3, 9, true);
  Skeleton frames;
  for (std::size_t f = 0; f < demo.truth.size(); f += 15) frames.push_back(demo.truth[f]);
  frames[2].ok[kRElbow] = false;  // one sample without a measurable arm: held and flagged
  RetargetOptions options;
  options.use_ceres = false;
  const std::vector<RetargetRow> rows = retargetSkeleton(arm, frames, options);
  CHECK((rows[2].flags & kRowHumanMissing) != 0);
  CHECK(rows[2].result.q_q == rows[1].result.q_q);
  const std::string path = (freshDir("pipeline_csv") / "retarget.csv").string();
  RetargetParams written = options.params;
  written.priority = RetargetPriority::kJoints;  // what is read back must be what was written
  written.lambda_q = 0.75;
  written.posture_weights << 1.0, 2.0, 0.5, 1.0, 0.25;
  writeRetargetCsv(path, rows, written);
  RetargetParams setting;
  const std::vector<RetargetRow> back = readRetargetCsv(path, &setting);
  CHECK(sameRetargetSetting(setting, written));
  REQUIRE(back.size() == rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    CHECK(back[i].flags == rows[i].flags);
    CHECK((back[i].result.q_q - rows[i].result.q_q).cwiseAbs().maxCoeff() < 1e-8);
    CHECK((back[i].result.q_r - rows[i].result.q_r).cwiseAbs().maxCoeff() < 1e-8);
    CHECK((back[i].target.p_target_TH - rows[i].target.p_target_TH).cwiseAbs().maxCoeff() < 1e-8);
  }
}
