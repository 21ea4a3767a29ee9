// Synthesiser: determinism, file formats, exact projections with the written calibration,
// truth angles consistent with the truth points, realistic noise.
#include "nao/human_kinematics.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"
#include "support/test_util.hpp"

#include <Eigen/Geometry>
#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>
#include <vector>

using namespace nao;
using nao::test::kDeg;
namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Relative path -> contents of every file under dir (sorted by path).
std::map<std::string, std::string> readTree(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = nao::test::readFile(e.path().string());
  return files;
}

int synth(const fs::path& out, std::uint64_t seed, int per_movement, bool noise_free,
          std::vector<tools::Movement> movements = {tools::Movement::kWholeArm, tools::Movement::kElbow,
                                                    tools::Movement::kWrist}) {
  tools::SynthOptions o;
  o.movements = movements;
  o.per_movement = per_movement;
  o.seed = seed;
  o.noise_free = noise_free;
  o.out_dir = out.string();
  std::ostringstream progress;
  return tools::synthesise(o, progress);
}

tools::CameraSet readCalibration(const fs::path& file) {
  const nlohmann::json j = nlohmann::json::parse(nao::test::readFile(file.string()));
  tools::CameraSet cams;
  for (const auto& c : j.at("cameras")) {
    tools::Camera cam;
    cam.name = c.at("name").get<std::string>();
    cam.width = c.at("size")[0].get<int>();
    cam.height = c.at("size")[1].get<int>();
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) cam.K(r, k) = c.at("matrix")[r][k].get<double>();
    for (int k = 0; k < 5; ++k) cam.dist[k] = c.at("distortions")[k].get<double>();
    const Eigen::Vector3d rvec(c.at("rotation")[0].get<double>(), c.at("rotation")[1].get<double>(),
                               c.at("rotation")[2].get<double>());
    cam.R_CW = Eigen::AngleAxisd(rvec.norm(), rvec.normalized()).toRotationMatrix();
    cam.p_CW = Eigen::Vector3d(c.at("translation")[0].get<double>(), c.at("translation")[1].get<double>(),
                               c.at("translation")[2].get<double>());
    cams.push_back(cam);
  }
  return cams;
}

std::vector<fs::path> sortedFiles(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir)) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

// The joint-angle and phase columns of truth.csv.
struct TruthAngles {
  std::vector<HumanJointVector> q;
  std::vector<int> phase;
};
TruthAngles readTruthAngles(const fs::path& file) {
  std::istringstream in(nao::test::readFile(file.string()));
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  {
    std::istringstream h(line);
    std::string cell;
    while (std::getline(h, cell, ',')) header.push_back(cell);
  }
  const auto col = [&](const std::string& name) {
    const auto it = std::find(header.begin(), header.end(), name);
    REQUIRE_MESSAGE(it != header.end(), "truth.csv: expected a column " << name);
    return static_cast<std::size_t>(it - header.begin());
  };
  std::size_t c_q[kNumHumanJoints];
  for (int j = 0; j < kNumHumanJoints; ++j) c_q[j] = col(kHumanJointNames[j]);
  const std::size_t c_phase = col("phase");
  REQUIRE(header.front() == "frame");
  TruthAngles out;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::istringstream r(line);
    std::string cell;
    while (std::getline(r, cell, ',')) cells.push_back(cell);
    REQUIRE(cells.size() == header.size());
    HumanJointVector q;
    for (int j = 0; j < kNumHumanJoints; ++j) q[j] = std::stod(cells[c_q[j]]);
    out.q.push_back(q);
    out.phase.push_back(std::stoi(cells[c_phase]));
  }
  return out;
}

}  // namespace

TEST_CASE("the same seed gives byte-identical files, another seed different ones") {
  const fs::path a = freshDir("synth_det_a"), b = freshDir("synth_det_b"), c = freshDir("synth_det_c");
  REQUIRE(synth(a, 42, 1, false) == 3);
  REQUIRE(synth(b, 42, 1, false) == 3);
  REQUIRE(synth(c, 43, 1, false) == 3);
  const auto files_a = readTree(a), files_b = readTree(b), files_c = readTree(c);
  REQUIRE(files_a.size() > 100);
  CHECK_MESSAGE(files_a.size() == files_b.size(), "expected " << files_a.size() << " files, got " << files_b.size());
  int n_differ = 0;
  for (const auto& [path, text] : files_a) {
    const auto it = files_b.find(path);
    if (it == files_b.end() || it->second != text) {
      ++n_differ;
      if (n_differ < 5) MESSAGE("differs between runs with the same seed: " << path);
    }
  }
  CHECK_MESSAGE(n_differ == 0, "expected 0 differing files, got " << n_differ);
  for (const std::string name : {"whole_arm_000/truth.csv", "elbow_000/calibration.json", "wrist_000/meta.json"}) {
    REQUIRE(files_c.count(name) == 1);
    CHECK_MESSAGE(files_c.at(name) != files_a.at(name), name << " expected to differ for another seed");
  }
  // Writing again into the same folder leaves the same files (old frames replaced, none stale).
  REQUIRE(synth(a, 43, 1, false) == 3);
  CHECK(readTree(a) == files_c);
}

TEST_CASE("the demonstration folders follow docs/formats.md and OpenPose JSON parses with 75 pose values") {
  const fs::path out = freshDir("synth_format");
  REQUIRE(synth(out, 5, 2, false, {tools::Movement::kWrist}) == 2);
  for (const std::string demo : {"wrist_000", "wrist_001"}) {
    const fs::path dir = out / demo;
    for (const std::string f : {"calibration.json", "truth.csv", "meta.json", "cam0", "cam1"})
      CHECK_MESSAGE(fs::exists(dir / f), "expected " << (dir / f).string());
    const TruthAngles truth = readTruthAngles(dir / "truth.csv");
    const tools::Skeleton skeleton = tools::readSkeletonCsv((dir / "truth.csv").string());
    REQUIRE(skeleton.size() == truth.q.size());
    const double duration = skeleton.back().t_s;
    CHECK_MESSAGE((duration > 8.0 && duration < 25.0), "expected a 8-25 s demonstration, got " << duration);
    // Phases run 0 -> 1 -> 2.
    CHECK(std::is_sorted(truth.phase.begin(), truth.phase.end()));
    CHECK(truth.phase.front() == 0);
    CHECK(truth.phase.back() == 2);
    CHECK(std::count(truth.phase.begin(), truth.phase.end(), 1) > 100);
    for (const auto& f : skeleton)
      for (int i = 0; i < kNumSkeletonPoints; ++i) REQUIRE(f.ok[i]);

    int n_dropped = 0, n_points = 0;
    for (const std::string cam : {"cam0", "cam1"}) {
      const std::vector<fs::path> files = sortedFiles(dir / cam);
      REQUIRE_MESSAGE(files.size() == truth.q.size(), "expected one JSON per frame (" << truth.q.size() << "), got "
                                                                                       << files.size());
      char expected[96];
      std::snprintf(expected, sizeof(expected), "%s_%012d_keypoints.json", demo.c_str(), 7);
      CHECK(files[7].filename().string() == expected);
      for (std::size_t k = 0; k < files.size(); k += 3) {
        const nlohmann::json j = nlohmann::json::parse(nao::test::readFile(files[k].string()));
        REQUIRE(j.at("people").size() == 1);
        const auto& person = j["people"][0];
        CHECK(person.at("person_id") == nlohmann::json::array({-1}));
        const auto& pose = person.at("pose_keypoints_2d");
        const auto& hand = person.at("hand_right_keypoints_2d");
        REQUIRE(pose.size() == 75);
        REQUIRE(hand.size() == 63);
        for (int i = 0; i < 25; ++i) {
          const double c = pose[3 * i + 2].get<double>();
          CHECK((c >= 0.0 && c <= 1.0));
          ++n_points;
          if (c == 0.0) {
            ++n_dropped;
            CHECK((pose[3 * i].get<double>() == 0.0 && pose[3 * i + 1].get<double>() == 0.0));
          }
        }
        for (int h = 0; h < 21; ++h)
          if (std::find(kHandKeypointIds.begin(), kHandKeypointIds.end(), h) == kHandKeypointIds.end())
            CHECK(hand[3 * h + 2].get<double>() == 0.0);
      }
    }
    CHECK_MESSAGE(n_dropped > 0, "expected some undetected keypoints with noise on");
    CHECK_MESSAGE(n_dropped < n_points / 5, "expected under 20% undetected, got " << n_dropped << " of " << n_points);
    const nlohmann::json meta = nlohmann::json::parse(nao::test::readFile((dir / "meta.json").string()));
    CHECK(meta.at("seed").get<std::uint64_t>() == 5u);
    CHECK(meta.at("movement").get<std::string>() == "wrist");
    CHECK(meta.at("n_frames").get<std::size_t>() == truth.q.size());
  }
}

TEST_CASE("projecting truth.csv with calibration.json reproduces the noise-free keypoints within 1e-6 px") {
  const fs::path out = freshDir("synth_noise_free");
  REQUIRE(synth(out, 9, 1, true) == 3);
  for (const std::string demo : {"whole_arm_000", "elbow_000", "wrist_000"}) {
    const fs::path dir = out / demo;
    const tools::CameraSet cams = readCalibration(dir / "calibration.json");
    REQUIRE(cams.size() == 2);
    CHECK(cams[0].width == 1920);
    const tools::Skeleton truth = tools::readSkeletonCsv((dir / "truth.csv").string());
    double max_err = 0.0;
    int n_seen = 0, n_arm_unseen = 0;
    for (std::size_t c = 0; c < 2; ++c) {
      const std::vector<fs::path> files = sortedFiles(dir / cams[c].name);
      REQUIRE(files.size() == truth.size());
      for (std::size_t k = 0; k < files.size(); k += 2) {
        const nlohmann::json person = nlohmann::json::parse(nao::test::readFile(files[k].string()))["people"][0];
        const auto check = [&](const nlohmann::json& arr, int slot, int point) {
          const double conf = arr[3 * slot + 2].get<double>();
          const Eigen::Vector2d px = tools::project(cams[c], truth[k].p_W[point]);
          const bool inside = tools::toCamera(cams[c], truth[k].p_W[point]).z() > 0.1 && px.x() >= 0 && px.y() >= 0 &&
                              px.x() < cams[c].width && px.y() < cams[c].height;
          if (conf == 0.0) {
            CHECK_MESSAGE(!inside, demo << " frame " << k << ": " << std::string(kSkeletonPointNames[point])
                                        << " inside the image but not written");
            return;
          }
          CHECK(conf == 1.0);
          const double err = (px - Eigen::Vector2d(arr[3 * slot].get<double>(), arr[3 * slot + 1].get<double>())).norm();
          max_err = std::max(max_err, err);
          ++n_seen;
        };
        for (int i = 0; i < kNumBody25; ++i) check(person["pose_keypoints_2d"], i, i);
        for (int h = 0; h < 4; ++h) check(person["hand_right_keypoints_2d"], kHandKeypointIds[h], kRHand0 + h);
        for (int i : {kRShoulder, kRElbow, kRWrist})
          if (person["pose_keypoints_2d"][3 * i + 2].get<double>() == 0.0) ++n_arm_unseen;
      }
    }
    CHECK_MESSAGE(max_err < 1e-6, demo << ": expected reprojection within 1e-6 px, got " << max_err);
    CHECK(n_seen > 1000);
    CHECK_MESSAGE(n_arm_unseen == 0, demo << ": the right arm must stay inside both images");
  }
}

TEST_CASE("truth.csv joint angles agree with its own 3D points within 0.5 deg") {
  const fs::path out = freshDir("synth_truth_angles");
  REQUIRE(synth(out, 17, 2, false) == 6);
  const HumanKinematicsConfig config;
  for (const std::string demo : {"whole_arm_000", "whole_arm_001", "elbow_000", "elbow_001", "wrist_000", "wrist_001"}) {
    const tools::Skeleton skeleton = tools::readSkeletonCsv((out / demo / "truth.csv").string());
    const TruthAngles truth = readTruthAngles(out / demo / "truth.csv");
    REQUIRE(skeleton.size() == truth.q.size());
    HumanArmData data;
    double max_err = 0.0;
    for (std::size_t k = 0; k < skeleton.size(); ++k) {
      humanArmKinematics(config, data, skeleton[k]);
      REQUIRE(data.valid);
      REQUIRE(data.flags == 0u);
      for (int j = 0; j < kNumHumanJoints; ++j)
        max_err = std::max(max_err, std::abs(std::remainder(data.q[j] - truth.q[k][j], 2.0 * kPi)));
    }
    CHECK_MESSAGE(max_err < 0.5 * kDeg, demo << ": expected < 0.5 deg, got " << max_err / kDeg << " deg");
  }
}

TEST_CASE("noisy keypoints scatter by a few pixels around the exact projection and confidences vary") {
  const tools::SynthDemo demo = tools::generateDemo(tools::Movement::kElbow, 3, 77, false);
  const std::vector<tools::OpenPoseFrame> frames = tools::renderCamera(demo, 1);
  std::vector<double> err;
  double c_min = 1.0, c_max = 0.0;
  for (std::size_t k = 0; k < frames.size(); ++k)
    for (int i = 0; i < kNumBody25; ++i) {
      const Eigen::Vector3d& o = frames[k].pose[i];
      if (o.z() == 0.0) continue;
      err.push_back((o.head<2>() - tools::project(demo.cameras[1], demo.truth[k].p_W[i])).norm());
      c_min = std::min(c_min, o.z());
      c_max = std::max(c_max, o.z());
    }
  std::sort(err.begin(), err.end());
  const double median = err[err.size() / 2];
  // Isotropic Gaussian of sigma s: the median distance is 1.18 s, s in [1, 2.5] px.
  CHECK_MESSAGE((median > 1.0 && median < 3.2), "expected a median pixel error of 1.2-3 px, got " << median);
  CHECK(c_min > 0.0);
  CHECK(c_max < 1.0);
  CHECK(c_max - c_min > 0.2);
}

TEST_CASE("bad synth options give a clear error") {
  tools::SynthOptions o;
  o.out_dir = "";
  std::ostringstream progress;
  CHECK_THROWS_AS(tools::synthesise(o, progress), tools::UserError);
  o.out_dir = freshDir("synth_bad").string();
  o.per_movement = 0;
  CHECK_THROWS_WITH_AS(tools::synthesise(o, progress), doctest::Contains("--per-movement"), tools::UserError);
  CHECK_THROWS_AS(tools::parseMovement("shoulder"), tools::UserError);
  CHECK(tools::parseMovement("elbow") == tools::Movement::kElbow);
}

TEST_CASE("sampled subjects have plausible anthropometrics") {
  double sum_h = 0.0;
  int n_female = 0;
  for (int i = 0; i < 80; ++i) {
    const tools::Anthropometrics b = tools::generateDemo(tools::Movement::kWholeArm, i, 1, true).body;
    sum_h += b.stature_m;
    n_female += b.female ? 1 : 0;
    CHECK((b.stature_m > 1.45 && b.stature_m < 1.95));
    CHECK(std::abs(b.upper_arm_m / b.stature_m - 0.186) < 0.186 * 0.08);
    CHECK(std::abs(b.forearm_m / b.stature_m - 0.146) < 0.146 * 0.08);
    CHECK((b.scale_m() > 0.5 && b.scale_m() < 0.8));
  }
  CHECK((sum_h / 80 > 1.62 && sum_h / 80 < 1.76));
  CHECK((n_female > 20 && n_female < 60));
}
