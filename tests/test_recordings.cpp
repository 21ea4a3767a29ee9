// The test recordings (tests/recordings): layout that `nao_toolchain triangulate --demo` reads,
// byte determinism, per-recording variation, realistic detections, and the movements' geometry.
#include "recordings.hpp"

#include "nao/tools/triangulate.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace nao;
namespace rec = nao::recordings;

namespace {

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / (name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Every file under `root`, relative path -> bytes.
std::map<std::string, std::string> readTree(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) files[fs::relative(e.path(), root).string()] = nao::test::readFile(e.path().string());
  return files;
}

double param(const rec::Recording& r, const std::string& name) {
  for (const auto& [n, v] : r.params)
    if (n == name) return v;
  FAIL("recording " << r.name << " has no parameter " << name);
  return 0.0;
}

// The torso frame of a truth frame (as the human kinematics build it, from the shoulders and MidHip).
Eigen::Matrix3d torsoAxes(const SkeletonFrame& f) {
  const Eigen::Vector3d mid = 0.5 * (f.p_W[kRShoulder] + f.p_W[kLShoulder]);
  const Eigen::Vector3d z = (mid - f.p_W[kMidHip]).normalized();
  Eigen::Vector3d y = f.p_W[kLShoulder] - f.p_W[kRShoulder];
  y = (y - z * z.dot(y)).normalized();
  Eigen::Matrix3d R;
  R << y.cross(z), y, z;
  return R;
}

}  // namespace

TEST_CASE("every movement's recording is what triangulate --demo reads: cam0/, cam1/, calibration.json, OpenPose file names, 6-10 s at 30 fps") {
  const fs::path out = freshDir("recordings_layout");
  for (const std::string movement : rec::kMovementNames) {
    CAPTURE(movement);
    const rec::Recording r = rec::generateRecording(movement, 0, 3);
    rec::writeRecording(r, out.string());
    const fs::path dir = out / r.name;
    REQUIRE(fs::is_regular_file(dir / "calibration.json"));
    for (const char* cam : {"cam0", "cam1"}) {
      std::vector<std::string> names;
      for (const auto& e : fs::directory_iterator(dir / cam)) names.push_back(e.path().filename().string());
      std::sort(names.begin(), names.end());
      REQUIRE(names.size() == r.truth.size());
      CHECK(names.front() == r.name + "_000000000000_keypoints.json");
      for (std::size_t k = 0; k < names.size(); ++k)
        CHECK(tools::openPoseFrameIndex(names[k]) == static_cast<long long>(k));
    }
    const double duration = r.truth.back().t_s;
    CHECK_MESSAGE(duration >= 6.0 - 1.0 / 30.0, r.name << " lasts " << duration << " s");
    CHECK_MESSAGE(duration <= 10.0, r.name << " lasts " << duration << " s");
    CHECK(std::abs(r.truth[1].t_s - r.truth[0].t_s - 1.0 / 30.0) < 1e-12);

    // The toolchain's own reader: the demonstration folder, its calibration and both cameras.
    tools::TriangulateOptions opt;
    tools::TriangulationReport report;
    const tools::Skeleton skeleton = tools::triangulateDemo(dir.string(), opt, &report);
    CHECK(report.n_frames == static_cast<int>(r.truth.size()));
    CHECK(report.n_frames_without_subject == 0);
    const int n_points = report.n_points_valid + report.n_points_missing + report.n_points_interpolated;
    const double valid_share = static_cast<double>(report.n_points_valid) / n_points;
    MESSAGE(r.name << ": " << skeleton.size() << " samples at 10 Hz, valid points " << 100.0 * valid_share
                   << " %, median reprojection " << report.median_reprojection_px << " px");
    CHECK_MESSAGE(valid_share > 0.9, "expected > 90 % valid points, got " << 100.0 * valid_share << " %");
    CHECK(report.median_reprojection_px < 3.0);
    // Against the truth: the right arm lands within a few centimetres (2 cameras, 1-2.5 px noise).
    int n_checked = 0, n_close = 0;
    for (const SkeletonFrame& f : skeleton) {
      const auto k = static_cast<std::size_t>(std::lround(f.t_s * 30.0));
      for (int i : {static_cast<int>(kRShoulder), static_cast<int>(kRElbow), static_cast<int>(kRWrist), static_cast<int>(kRHand9)}) {
        if (!f.ok[i] || k >= r.truth.size()) continue;
        ++n_checked;
        n_close += (f.p_W[i] - r.truth[k].p_W[i]).norm() < 0.04;
      }
    }
    CHECK_MESSAGE(n_close >= 0.97 * n_checked, n_close << " of " << n_checked << " arm points within 4 cm of the truth");
  }
  fs::remove_all(out);
}

TEST_CASE("the same seed writes byte-identical recordings, another seed different ones") {
  const fs::path a = freshDir("recordings_det_a"), b = freshDir("recordings_det_b"), c = freshDir("recordings_det_c");
  std::ostringstream log;
  rec::Options options;
  options.per_movement = 2;
  options.seed = 7;
  options.out_dir = a.string();
  CHECK(rec::writeRecordings(options, log) == 6);
  options.out_dir = b.string();
  rec::writeRecordings(options, log);
  options.seed = 8;
  options.out_dir = c.string();
  rec::writeRecordings(options, log);
  const auto files_a = readTree(a), files_b = readTree(b), files_c = readTree(c);
  REQUIRE(files_a.size() > 6 * 2 * 180);
  CHECK(files_a.size() == files_b.size());
  int n_differ = 0;
  for (const auto& [name, bytes] : files_a) {
    const auto it = files_b.find(name);
    n_differ += it == files_b.end() || it->second != bytes;
  }
  CHECK_MESSAGE(n_differ == 0, n_differ << " files differ between two runs of the same seed");
  const std::string calibration = "wave_000/calibration.json";
  REQUIRE(files_c.count(calibration) == 1);
  CHECK(files_c.at(calibration) != files_a.at(calibration));
  for (const fs::path& p : {a, b, c}) fs::remove_all(p);
}

TEST_CASE("recordings differ in subject size, duration, amplitude, speed and start pose") {
  const struct {
    const char* movement;
    const char* amplitude;
    const char* speed;
  } kinds[] = {{"wave", "swing_deg", "wave_hz"}, {"reach", "azimuth_deg", "reach_s"}, {"side_raise", "top_deg", "up_s"}};
  for (const auto& kind : kinds) {
    const std::string movement = kind.movement;
    CAPTURE(movement);
    std::vector<double> stature, duration, amplitude, speed, start_elbow;
    for (int i = 0; i < 8; ++i) {
      const rec::Recording r = rec::generateRecording(kind.movement, i, 11);
      stature.push_back(r.subject.stature_m);
      duration.push_back(r.truth.back().t_s);
      amplitude.push_back(param(r, kind.amplitude));
      speed.push_back(param(r, kind.speed));
      const SkeletonFrame& f = r.truth.front();
      start_elbow.push_back((f.p_W[kRElbow] - f.p_W[kRShoulder]).normalized().dot((f.p_W[kRWrist] - f.p_W[kRElbow]).normalized()));
    }
    auto spread = [](const std::vector<double>& v) {
      return *std::max_element(v.begin(), v.end()) - *std::min_element(v.begin(), v.end());
    };
    CHECK_MESSAGE(spread(stature) > 0.08, "stature spread " << spread(stature) << " m");
    CHECK_MESSAGE(spread(duration) > 1.0, "duration spread " << spread(duration) << " s");
    CHECK(spread(amplitude) > 0.0);
    CHECK(spread(speed) > 0.0);
    CHECK(spread(start_elbow) > 0.0);
    CHECK(std::set<double>(duration.begin(), duration.end()).size() == duration.size());
  }
}

TEST_CASE("detections are realistic: 1-2.5 px noise, confidences in (0, 1), a few dropouts, hand points 0, 5, 9, 17 only") {
  const rec::Recording r = rec::generateRecording("wave", 2, 5);
  REQUIRE(r.cameras.size() == 2u);
  for (int c = 0; c < 2; ++c) {
    const tools::Camera& cam = r.cameras[static_cast<std::size_t>(c)];
    const std::vector<rec::Detections> frames = rec::renderCamera(r, c);
    REQUIRE(frames.size() == r.truth.size());
    double sum2 = 0.0;
    int n_seen = 0, n_dropped = 0, n_hand_missed = 0, n_bad_confidence = 0, n_other_hand = 0;
    for (std::size_t k = 0; k < frames.size(); ++k) {
      for (int i = 0; i < kNumBody25; ++i) {
        const Eigen::Vector3d& d = frames[k].pose[static_cast<std::size_t>(i)];
        if (d.z() <= 0.0) {
          ++n_dropped;
          continue;
        }
        ++n_seen;
        sum2 += (d.head<2>() - tools::project(cam, r.truth[k].p_W[i])).squaredNorm();
        n_bad_confidence += !(d.z() > 0.0 && d.z() < 1.0);
      }
      bool any_hand = false;
      for (int h = 0; h < 21; ++h) {
        const bool used = std::find(kHandKeypointIds.begin(), kHandKeypointIds.end(), h) != kHandKeypointIds.end();
        const bool seen = frames[k].hand_right[static_cast<std::size_t>(h)].z() > 0.0;
        n_other_hand += seen && !used;
        any_hand |= seen;
      }
      n_hand_missed += !any_hand;
    }
    const double rms_px = std::sqrt(sum2 / (2.0 * n_seen));
    const double dropout = static_cast<double>(n_dropped) / (n_seen + n_dropped);
    MESSAGE("camera " << c << ": noise " << rms_px << " px per axis (sampled " << r.noise.pixel_sigma_px << "), dropouts "
                      << 100.0 * dropout << " %, hands missed in " << n_hand_missed << " of " << frames.size() << " frames");
    CHECK(std::abs(rms_px - r.noise.pixel_sigma_px) < 0.15 * r.noise.pixel_sigma_px);
    CHECK(dropout > 0.002);
    CHECK(dropout < 0.05);
    CHECK(n_bad_confidence == 0);
    CHECK(n_other_hand == 0);
    CHECK(n_hand_missed > 0);
    CHECK(n_hand_missed < static_cast<int>(frames.size()) / 10);
  }
}

TEST_CASE("the movements draw what they are named for: the wave's hand above the shoulder, the reach at shoulder height and still, the side raise through the horizontal") {
  for (int i = 0; i < 6; ++i) {
    CAPTURE(i);
    // Wave: while waving (the middle of the recording) the palm is above the shoulder.
    const rec::Recording wave = rec::generateRecording("wave", i, 21);
    const SkeletonFrame& mid = wave.truth[wave.truth.size() / 2];
    const Eigen::Matrix3d R = torsoAxes(mid);
    const double above = (R.transpose() * (mid.p_W[kRHand9] - mid.p_W[kRShoulder])).z();
    CHECK_MESSAGE(above > 0.05, wave.name << ": hand " << above << " m above the shoulder");

    // Reach: the highest forward reach puts the hand at shoulder height (+-8 cm), in front, and
    // the hand rests there for at least half a second.
    const rec::Recording reach = rec::generateRecording("reach", i, 21);
    double best_forward = -1.0, height = 0.0;
    std::size_t k_best = 0;
    for (std::size_t k = 0; k < reach.truth.size(); ++k) {
      const SkeletonFrame& f = reach.truth[k];
      const Eigen::Vector3d p = torsoAxes(f).transpose() * (f.p_W[kRHand9] - f.p_W[kRShoulder]);
      if (p.x() > best_forward) {
        best_forward = p.x();
        height = p.z();
        k_best = k;
      }
    }
    CHECK_MESSAGE(best_forward > 0.45, reach.name << ": hand only " << best_forward << " m forward");
    CHECK_MESSAGE(std::abs(height) < 0.08, reach.name << ": hand " << height << " m from shoulder height");
    int n_still = 0;
    for (std::size_t k = 1; k < reach.truth.size(); ++k)
      n_still += (reach.truth[k].p_W[kRHand9] - reach.truth[k - 1].p_W[kRHand9]).norm() < 0.003 &&
                 (reach.truth[k].p_W[kRHand9] - reach.truth[k_best].p_W[kRHand9]).norm() < 0.05;
    CHECK_MESSAGE(n_still >= 15, reach.name << ": the hand rests at the target for " << n_still << " frames");

    // Side raise: the elbow rises to the shoulder's height or above.
    const rec::Recording raise = rec::generateRecording("side_raise", i, 21);
    double top = -1.0;
    for (const SkeletonFrame& f : raise.truth) top = std::max(top, (torsoAxes(f).transpose() * (f.p_W[kRElbow] - f.p_W[kRShoulder])).z());
    CHECK_MESSAGE(top > -0.06, raise.name << ": the elbow stays " << -top << " m below the shoulder");
  }
}

TEST_CASE("nao_test_recordings writes the recordings it is asked for and rejects bad input with one line and status 2") {
  const fs::path out = freshDir("recordings_cli");
  const std::string exe = NAO_TEST_RECORDINGS_EXE;
  const std::string log = (out / "log.txt").string();
  const std::string ok = "'" + exe + "' --out '" + (out / "rec").string() + "' --movements wave,reach --per-movement 2 --seed 4 >'" + log + "' 2>&1";
  REQUIRE_MESSAGE(std::system(ok.c_str()) == 0, nao::test::readFile(log));
  std::set<std::string> dirs;
  for (const auto& e : fs::directory_iterator(out / "rec")) dirs.insert(e.path().filename().string());
  CHECK(dirs == std::set<std::string>{"reach_000", "reach_001", "wave_000", "wave_001"});
  const nlohmann::json meta = nlohmann::json::parse(nao::test::readFile((out / "rec" / "wave_001" / "meta.json").string()));
  CHECK(meta["seed"] == 4);
  CHECK(meta["movement"] == "wave");
  // The library and the executable write the same bytes.
  rec::writeRecording(rec::generateRecording("wave", 1, 4), (out / "lib").string());
  CHECK(readTree(out / "lib" / "wave_001") == readTree(out / "rec" / "wave_001"));

  for (const std::string bad : {"--movements circle", "--per-movement 0", "--seed x", "--frobnicate 1"}) {
    CAPTURE(bad);
    const std::string cmd = "'" + exe + "' --out '" + (out / "bad").string() + "' " + bad + " >'" + log + "' 2>&1";
    const int status = std::system(cmd.c_str());
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 2);
    const std::string text = nao::test::readFile(log);
    CHECK_MESSAGE(std::count(text.begin(), text.end(), '\n') == 1, "expected one line, got: " << text);
  }
  fs::remove_all(out);
}
