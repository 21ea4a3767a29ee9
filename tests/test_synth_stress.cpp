// The stress recordings (synth_stress.hpp): deterministic, the faults they promise are there,
// each right-arm point keeps two correct views, and written files read back as rendered.
#include "nao/tools/calibration.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/synth_stress.hpp"

#include <doctest/doctest.h>

#include <filesystem>

using namespace nao;
using namespace nao::tools;
namespace fs = std::filesystem;

TEST_CASE("a stress recording is a deterministic function of the demonstration and the seed") {
  const SynthDemo demo = generateDemo(Movement::kWrist, 2, 99, false);
  StressOptions opt;
  opt.n_frames = 120;
  const StressScene a = renderStressScene(demo, opt), b = renderStressScene(demo, opt);
  REQUIRE(a.truth.size() == 120);
  REQUIRE(a.keypoints.size() == 4);
  for (std::size_t c = 0; c < 4; ++c)
    for (std::size_t k = 0; k < 120; ++k) {
      const auto& pa = a.keypoints[c].frames[k].people;
      const auto& pb = b.keypoints[c].frames[k].people;
      REQUIRE(pa.size() == pb.size());
      for (std::size_t p = 0; p < pa.size(); ++p) {
        CHECK(pa[p].confidence == pb[p].confidence);
        for (int i = 0; i < kNumSkeletonPoints; ++i) CHECK(pa[p].px[i] == pb[p].px[i]);
      }
    }
  opt.seed = 2;
  const StressScene other = renderStressScene(demo, opt);
  CHECK(other.keypoints[0].frames[5].people[0].px[kNose] != a.keypoints[0].frames[5].people[0].px[kNose]);
}

TEST_CASE("a stress recording holds what it promises: two people in random order, faults, two correct arm views") {
  const SynthDemo demo = generateDemo(Movement::kElbow, 0, 5, false);
  const StressScene s = renderStressScene(demo, StressOptions{});
  const std::size_t n = s.truth.size();
  REQUIRE(n > 500);  // the whole demonstration at 60 fps
  CHECK(s.truth[1].t_s == doctest::Approx(1.0 / 60.0));
  int subject_second = 0, both = 0;
  for (std::size_t k = 0; k < n; ++k) {
    for (int i : {kRShoulder, kRElbow, kRWrist}) CHECK(__builtin_popcount(s.correct_views[k][static_cast<std::size_t>(i)]) >= 2);
    for (std::size_t c = 0; c < s.cameras.size(); ++c) {
      both += s.subject_index[k][c] >= 0 && s.bystander_index[k][c] >= 0;
      subject_second += s.subject_index[k][c] == 1;
    }
  }
  CHECK(both > static_cast<int>(n));            // the second person is in view most of the time
  CHECK(subject_second > static_cast<int>(n));  // and the subject is not always people[0]
  CHECK(s.n_swapped_frames > static_cast<int>(n) / 10);
  CHECK(s.n_wrong_keypoints > static_cast<int>(n) / 20);
  CHECK(s.n_hidden_points > 100);
  // Written and read back: the same cameras and detections (pixels to 1e-3 px).
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / "synth_stress";
  fs::remove_all(dir);
  StressOptions short_opt;
  short_opt.n_frames = 30;
  const StressScene small = renderStressScene(demo, short_opt);
  writeStressScene(small, dir.string());
  const CameraSet cams = readCalibration((dir / small.name / "calibration.json").string());
  REQUIRE(cams.size() == 4);
  for (std::size_t c = 0; c < 4; ++c) {
    CHECK((cams[c].R_CW - small.cameras[c].R_CW).cwiseAbs().maxCoeff() < 1e-12);
    const CameraKeypoints kp = readOpenPoseFolder((dir / small.name / ("cam" + std::to_string(c))).string(), PoseFormat::kBody25);
    REQUIRE(kp.frames.size() == 30);
    for (std::size_t k = 0; k < 30; ++k) {
      REQUIRE(kp.frames[k].people.size() == small.keypoints[c].frames[k].people.size());
      for (std::size_t p = 0; p < kp.frames[k].people.size(); ++p)
        for (int i = 0; i < kNumSkeletonPoints; ++i) {
          const Person2d& got = kp.frames[k].people[p];
          const Person2d& want = small.keypoints[c].frames[k].people[p];
          CHECK(got.detected(i) == want.detected(i));
          if (got.detected(i)) CHECK((got.px[i] - want.px[i]).norm() < 1e-3);
        }
    }
  }
}
