// Triangulation against synthetic scenes with known 3D truth: a standing human upper body seen
// by two or three cameras (camera.hpp's project()), written as OpenPose JSON, read back and
// triangulated. Covers exactness, noise (checked against the Cramer-Rao bound), subject
// selection, undetected and one-camera points, BODY_25B, outlier rejection, resampling, frame
// pairing by file index (frame files absent in some or all cameras) and the refinement's guard;
// camera selection by consensus, image-size tolerances and the gap policy (the stress
// recordings, the low-pass and the bone fit: test_triangulate_stress.cpp).
#include "nao/human_kinematics.hpp"
#include "nao/tools/calibration.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/synth_stress.hpp"
#include "nao/tools/triangulate.hpp"
#include "support/triangulation_scene.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace nao;
using namespace nao::tools;
using namespace nao::test;
namespace fs = std::filesystem;

constexpr double kHalfMm = 0.5e-3;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / "triangulate" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void writeText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

// (camera, frame) pairs whose file is not written; camera -1 means every camera.
using AbsentFiles = std::vector<std::pair<int, int>>;

bool isAbsent(const AbsentFiles& absent, int cam, int frame) {
  return std::find(absent.begin(), absent.end(), std::make_pair(cam, frame)) != absent.end() ||
         std::find(absent.begin(), absent.end(), std::make_pair(-1, frame)) != absent.end();
}

// A demonstration folder like the synthesiser's: calibration.json and cam<i>/ OpenPose files.
fs::path writeDemo(const std::string& name, const Capture& c, PoseFormat format = PoseFormat::kBody25,
                   const AbsentFiles& absent = {}) {
  const fs::path dir = freshDir(name);
  writeText(dir / "calibration.json", formatCalibrationJson(c.cams));
  for (std::size_t cam = 0; cam < c.cams.size(); ++cam) {
    const fs::path cam_dir = dir / ("cam" + std::to_string(cam));
    fs::create_directories(cam_dir);
    for (std::size_t k = 0; k < c.people.size(); ++k) {
      if (isAbsent(absent, static_cast<int>(cam), static_cast<int>(k))) continue;
      char file[64];
      std::snprintf(file, sizeof file, "%s_%012zu_keypoints.json", name.c_str(), k);
      writeText(cam_dir / file, formatOpenPoseJson(c.people[k][cam], format));
    }
  }
  return dir;
}

TriangulateOptions captureRate() {
  TriangulateOptions opt;
  opt.rate_hz = opt.fps;  // one output sample per capture frame
  opt.max_gap_s = 0.0;    // per-frame rules; the gap policy has its own tests
  return opt;
}

// Every point valid and within `tol` of the truth, except those listed as expected missing.
void checkAgainstTruth(const Skeleton& s, const std::vector<Points>& truth, double tol,
                       const std::vector<std::pair<int, int>>& expected_missing = {}) {
  REQUIRE(s.size() == truth.size());
  double worst = 0.0;
  for (std::size_t k = 0; k < s.size(); ++k) {
    CHECK(s[k].t_s == doctest::Approx(static_cast<double>(k) / 30.0));
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      const bool missing = std::find(expected_missing.begin(), expected_missing.end(),
                                     std::make_pair(static_cast<int>(k), i)) != expected_missing.end();
      if (missing) {
        CHECK_MESSAGE(!s[k].ok[i], "frame " << k << " point " << kSkeletonPointNames[i] << " should be missing");
        continue;
      }
      CHECK_MESSAGE(s[k].ok[i], "frame " << k << " point " << kSkeletonPointNames[i] << " is missing");
      if (!s[k].ok[i]) continue;
      const double e = error(s[k], truth[k], i);
      worst = std::max(worst, e);
      CHECK_MESSAGE(e < tol, "frame " << k << " point " << kSkeletonPointNames[i] << " off by " << e * 1e3 << " mm");
    }
  }
  MESSAGE("largest error " << worst * 1e3 << " mm");
}

}  // namespace

TEST_CASE("undistortPixel inverts the camera's distortion and intrinsics") {
  for (const Camera& cam : cameras(3))
    for (double x = -0.6; x <= 0.6; x += 0.1)
      for (double y = -0.4; y <= 0.4; y += 0.1) {
        const Eigen::Vector2d xd = distort(cam, Eigen::Vector2d(x, y));
        const Eigen::Vector2d px(cam.K(0, 0) * xd.x() + cam.K(0, 2), cam.K(1, 1) * xd.y() + cam.K(1, 2));
        CHECK((undistortPixel(cam, px) - Eigen::Vector2d(x, y)).norm() < 1e-12);
      }
}

TEST_CASE("DLT and the Ceres refinement each recover a noise-free point; the refinement converges from 10 cm off") {
  const CameraSet cams = cameras(3);
  const Eigen::Vector3d p_W(0.12, -0.3, 1.25);
  std::vector<Observation> obs;
  for (int c = 0; c < 3; ++c) obs.push_back({c, project(cams[static_cast<std::size_t>(c)], p_W), 0.5 + 0.2 * c});
  const std::optional<Eigen::Vector3d> dlt = triangulateDlt(cams, obs);
  REQUIRE(dlt);
  CHECK((*dlt - p_W).norm() < 1e-9);
  const Eigen::Vector3d refined = refineOnReprojection(cams, obs, p_W + Eigen::Vector3d(0.1, -0.05, 0.08), 30);
  CHECK((refined - p_W).norm() < 1e-9);
  CHECK_FALSE(triangulateDlt(cams, {obs[0]}));  // one view: nothing
}

TEST_CASE("noise-free views of a moving subject triangulate within 0.5 mm (2 and 3 cameras, via JSON files)") {
  for (int n_cameras : {2, 3}) {
    CAPTURE(n_cameras);
    const Capture c = subjectOnly(n_cameras, 15);
    TriangulationReport report;
    const Skeleton s = triangulateDemo(writeDemo("exact" + std::to_string(n_cameras), c).string(), captureRate(), &report);
    checkAgainstTruth(s, c.truth, kHalfMm);
    CHECK(report.n_frames == 15);
    CHECK(report.n_observations_rejected == 0);
    CHECK(report.n_bone_rejections == 0);
    CHECK(report.median_reprojection_px < 1e-6);
  }
}

TEST_CASE("with sigma = 2 px pixel noise the median 3D error stays below the Cramer-Rao RMS bound") {
  // Bound: for Gaussian pixel noise the maximum-likelihood point (what DLT + Ceres on equally
  // weighted reprojection errors computes) has, to first order, covariance
  // sigma^2 (sum_c J_c^T J_c)^-1 with J_c the 2x3 projection Jacobian. Its RMS 3D error
  // sqrt(trace) is computed here per point from the geometry, independently of the
  // triangulation code. The median of a 3D Gaussian error's norm is below its RMS (0.67 RMS
  // for one dominant axis up to 0.89 RMS isotropic), so median(measured) <= median(RMS bound)
  // must hold with margin; the lower bound 0.3 x catches a test that applies no noise.
  // Here (2 cameras 3.3 m away, f = 900 px, 46 deg apart) the bound is ~1.4 cm, mostly depth.
  const double sigma = 2.0;
  Capture c = subjectOnly(2, 40, /*equal_confidence=*/true);
  std::mt19937_64 rng(20261121);
  std::normal_distribution<double> noise(0.0, sigma);
  for (FramePeople& frame : c.people)
    for (std::vector<Person2d>& cam : frame)
      for (int i = 0; i < kNumSkeletonPoints; ++i) cam[0].px[i] += Eigen::Vector2d(noise(rng), noise(rng));
  TriangulationReport report;
  const Skeleton s = triangulateDemo(writeDemo("noisy", c).string(), captureRate(), &report);
  REQUIRE(s.size() == c.truth.size());

  std::vector<double> errors, bounds;
  for (std::size_t k = 0; k < s.size(); ++k)
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      Eigen::Matrix3d fisher = Eigen::Matrix3d::Zero();
      for (const Camera& cam : c.cams) {
        Eigen::Matrix<double, 2, 3> J;
        for (int a = 0; a < 3; ++a) {
          Eigen::Vector3d h = Eigen::Vector3d::Zero();
          h[a] = 1e-6;
          J.col(a) = (project(cam, c.truth[k][static_cast<std::size_t>(i)] + h) -
                      project(cam, c.truth[k][static_cast<std::size_t>(i)] - h)) / 2e-6;
        }
        fisher += J.transpose() * J / (sigma * sigma);
      }
      bounds.push_back(std::sqrt(fisher.inverse().trace()));
      if (s[k].ok[i]) errors.push_back(error(s[k], c.truth[k], i));
    }
  const auto med = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const double median_error = med(errors), median_bound = med(bounds);
  MESSAGE("sigma 2 px, 2 cameras: median 3D error " << median_error * 1e3 << " mm, median CRB RMS "
                                                   << median_bound * 1e3 << " mm, valid " << errors.size() << "/"
                                                   << bounds.size() << ", median reprojection "
                                                   << report.median_reprojection_px << " px");
  CHECK(median_error <= median_bound);
  CHECK(median_error >= 0.3 * median_bound);
  // Noise this small must not make points missing (outlier gate 10 px = 7 sigma of the
  // residual, bone tolerance >= 5 cm = 3.5 x the bound): at most 1 % lost.
  CHECK(static_cast<double>(errors.size()) >= 0.99 * static_cast<double>(bounds.size()));
}

TEST_CASE("the subject is chosen by multi-view consistency when it is not people[0]") {
  // cam0: a bystander at the image edge (partly outside), a second person fully visible behind
  // the subject, then the subject; cam1: a spurious partial body (three of the subject's
  // points displaced), the background person, junk, and the subject. Order shuffled per frame.
  Capture c = subjectOnly(2, 12);
  std::mt19937_64 rng(7);
  for (std::size_t k = 0; k < c.people.size(); ++k) {
    const double t = static_cast<double>(k) / 30.0;
    const Points edge_bystander = body(t + 1.0, Eigen::Vector3d(0.2, 2.6, 0.0));
    const Points background = body(t + 2.0, Eigen::Vector3d(-1.5, 1.0, 0.0));
    for (std::size_t cam = 0; cam < 2; ++cam) {
      std::vector<Person2d>& people = c.people[k][cam];
      people.push_back(view(c.cams[cam], edge_bystander, static_cast<int>(k), static_cast<int>(cam)));
      people.push_back(view(c.cams[cam], background, static_cast<int>(k), static_cast<int>(cam)));
      if (cam == 1) {
        Person2d partial;
        for (int i : {kRShoulder, kRElbow, kRWrist}) {
          partial.px[i] = people[0].px[i] + Eigen::Vector2d(35.0, -20.0);
          partial.confidence[i] = 0.6;
        }
        people.push_back(partial);
        Person2d junk;
        for (int i : {kNeck, kLHip, kNose}) junk.px[i] = Eigen::Vector2d(100.0 + 30 * i, 900.0), junk.confidence[i] = 0.3;
        people.push_back(junk);
      }
      std::shuffle(people.begin(), people.end(), rng);
      for (Person2d& p : people) p.person_id = -1;
    }
  }
  const fs::path dir = writeDemo("multi", c);
  const Skeleton s = triangulateDemo(dir.string(), captureRate());
  checkAgainstTruth(s, c.truth, kHalfMm);

  // Frame 0 on its own (no continuity): the same choice, by consistency and centrality.
  const CameraKeypoints cam0 = readOpenPoseFolder((dir / "cam0").string(), PoseFormat::kBody25);
  const CameraKeypoints cam1 = readOpenPoseFolder((dir / "cam1").string(), PoseFormat::kBody25);
  const SubjectChoice choice = chooseSubject(c.cams, {&cam0.frames[0].people, &cam1.frames[0].people}, std::nullopt, {});
  REQUIRE(choice.found);
  CHECK((choice.centre_W - c.truth[0][kNeck]).norm() < 0.5);
  // Continuity wins over centrality: starting from the background person, it is kept.
  const Points background0 = body(2.0, Eigen::Vector3d(-1.5, 1.0, 0.0));
  const SubjectChoice kept = chooseSubject(c.cams, {&cam0.frames[0].people, &cam1.frames[0].people},
                                           background0[kNeck], {});
  REQUIRE(kept.found);
  CHECK((kept.centre_W - background0[kNeck]).norm() < 0.3);
}

TEST_CASE("0,0,0 keypoints and points seen by one camera are missing, never invented") {
  SUBCASE("two cameras") {
    Capture c = subjectOnly(2, 10);
    std::vector<std::pair<int, int>> missing;
    for (int k = 2; k <= 4; ++k) c.people[k][1][0].confidence[kRElbow] = 0.0, missing.emplace_back(k, kRElbow);
    c.people[5][0][0].confidence[kLWrist] = 0.0, missing.emplace_back(5, kLWrist);
    c.people[6][0][0].confidence[kRHand17] = 0.0, c.people[6][1][0].confidence[kRHand17] = 0.0;
    missing.emplace_back(6, kRHand17);
    c.people[7][1][0].confidence[kRWrist] = 0.01, missing.emplace_back(7, kRWrist);  // below min_confidence
    c.people[8][0].clear(), c.people[8][1].clear();  // nobody detected in frame 8
    for (int i = 0; i < kNumSkeletonPoints; ++i) missing.emplace_back(8, i);
    TriangulationReport report;
    const Skeleton s = triangulateDemo(writeDemo("undetected2", c).string(), captureRate(), &report);
    checkAgainstTruth(s, c.truth, kHalfMm, missing);
    CHECK(report.n_frames_without_subject == 1);
    for (const auto& [k, i] : missing) CHECK(s[static_cast<std::size_t>(k)].p_W[static_cast<std::size_t>(i)] == Eigen::Vector3d::Zero());
  }
  SUBCASE("three cameras: one view lost is fine, two lost is missing") {
    Capture c = subjectOnly(3, 6);
    c.people[1][2][0].confidence[kRWrist] = 0.0;                                   // still 2 views
    c.people[2][1][0].confidence[kRWrist] = 0.0, c.people[2][2][0].confidence[kRWrist] = 0.0;  // 1 view
    const Skeleton s = triangulateDemo(writeDemo("undetected3", c).string(), captureRate());
    checkAgainstTruth(s, c.truth, kHalfMm, {{2, kRWrist}});
  }
}

TEST_CASE("BODY_25B files map onto BODY_25 names, MidHip from the 3D hips' mean") {
  // Written with the test's own BODY_25B order (OpenPose's part list), not the library table.
  const std::array<int, 25> b25b = {kNose,  kLEye,  kREye,   kLEar,   kREar,      kLShoulder, kRShoulder,
                                    kLElbow, kRElbow, kLWrist, kRWrist, kLHip,      kRHip,      kLKnee,
                                    kRKnee, kLAnkle, kRAnkle, -17 /* UpperNeck */, -18 /* HeadTop */,
                                    kLBigToe, kLSmallToe, kLHeel, kRBigToe, kRSmallToe, kRHeel};
  Capture c = subjectOnly(2, 8);
  const fs::path dir = freshDir("body25b");
  writeText(dir / "calibration.json", formatCalibrationJson(c.cams));
  std::vector<Eigen::Vector3d> upper_neck;
  for (std::size_t cam = 0; cam < 2; ++cam) {
    fs::create_directories(dir / ("cam" + std::to_string(cam)));
    for (std::size_t k = 0; k < c.truth.size(); ++k) {
      const Points& t = c.truth[k];
      if (cam == 0) upper_neck.push_back(t[kNeck] + Eigen::Vector3d(0.01, 0.0, 0.07));
      nlohmann::json pose = nlohmann::json::array();
      for (int slot : b25b) {
        const Eigen::Vector3d p = slot == -17 ? upper_neck[k] : slot == -18 ? Eigen::Vector3d(t[kNose] + Eigen::Vector3d(-0.08, 0, 0.14))
                                                                            : t[static_cast<std::size_t>(slot)];
        const Eigen::Vector2d px = project(c.cams[cam], p);
        pose.push_back(px.x()), pose.push_back(px.y()), pose.push_back(0.8);
      }
      nlohmann::json person = nlohmann::json::object();
      person["person_id"] = nlohmann::json::array({-1});
      person["pose_keypoints_2d"] = pose;
      nlohmann::json doc = nlohmann::json::object();
      doc["people"] = nlohmann::json::array({person});
      writeText(dir / ("cam" + std::to_string(cam)) / ("b." + std::to_string(k) + ".json"), doc.dump());
    }
  }
  TriangulateOptions opt = captureRate();
  opt.format = PoseFormat::kBody25B;
  const Skeleton s = triangulateDemo(dir.string(), opt);
  REQUIRE(s.size() == c.truth.size());
  for (std::size_t k = 0; k < s.size(); ++k) {
    for (int slot : b25b) {
      if (slot < 0) continue;
      REQUIRE(s[k].ok[slot]);
      CHECK_MESSAGE(error(s[k], c.truth[k], slot) < kHalfMm, kSkeletonPointNames[slot] << " misplaced");
    }
    REQUIRE(s[k].ok[kNeck]);
    CHECK((s[k].p_W[kNeck] - upper_neck[k]).norm() < kHalfMm);
    REQUIRE(s[k].ok[kMidHip]);
    const Eigen::Vector3d hips_mean = 0.5 * (c.truth[k][kRHip] + c.truth[k][kLHip]);
    CHECK((s[k].p_W[kMidHip] - hips_mean).norm() < kHalfMm);
    CHECK((c.truth[k][kMidHip] - hips_mean).norm() > 0.009);  // the truth's own MidHip differs
    for (int h = 0; h < 4; ++h) CHECK_FALSE(s[k].ok[kRHand0 + h]);  // no hand array written
  }
  // Read as BODY_25 the same files put the right shoulder where BODY_25B has the right eye.
  const Skeleton wrong = triangulateDemo(dir.string(), captureRate());
  CHECK((wrong[0].p_W[kRShoulder] - c.truth[0][kRShoulder]).norm() > 0.1);
}

TEST_CASE("three cameras: a confident wrong keypoint in one camera is rejected and the point stays exact") {
  Capture c = subjectOnly(3, 10);
  for (FramePeople& frame : c.people) {
    frame[2][0].px[kRWrist] += Eigen::Vector2d(45.0, -30.0);
    frame[2][0].confidence[kRWrist] = 0.97;
  }
  c.people[3][0][0].px[kLElbow] += Eigen::Vector2d(0.0, 40.0);
  TriangulationReport report;
  const Skeleton s = triangulateDemo(writeDemo("outlier3", c).string(), captureRate(), &report);
  checkAgainstTruth(s, c.truth, kHalfMm);
  CHECK(report.n_observations_rejected == 11);
  // Without the rule the same observations give a point centimetres off.
  std::vector<Observation> obs;
  for (int cam = 0; cam < 3; ++cam) {
    const Person2d& p = c.people[0][static_cast<std::size_t>(cam)][0];
    obs.push_back({cam, p.px[kRWrist], p.confidence[kRWrist]});
  }
  TriangulateOptions no_rule;
  no_rule.outlier_px = 1e9;
  const PointEstimate pulled = triangulatePoint(c.cams, obs, no_rule);
  REQUIRE(pulled.ok);
  CHECK((pulled.p_W - c.truth[0][kRWrist]).norm() > 0.01);
  const PointEstimate kept = triangulatePoint(c.cams, obs, TriangulateOptions{});
  CHECK(kept.n_rejected == 1);
  CHECK(kept.n_used == 2);
}

TEST_CASE("two cameras: a wrong keypoint is marked missing, not triangulated to a wrong place") {
  // Off the epipolar line the two rays miss each other (reprojection error): missing. Along the
  // epipolar line geometry cannot see it; the bone-length rule does (forearm and hand bones).
  Capture c = subjectOnly(2, 12);
  c.people[4][1][0].px[kRWrist] += Eigen::Vector2d(0.0, 40.0);
  const Camera& cam0 = c.cams[0];
  const Eigen::Vector3d C0_W = -cam0.R_CW.transpose() * cam0.p_CW;
  const Eigen::Vector3d true_wrist = c.truth[8][kRWrist];
  const Eigen::Vector3d false_wrist = true_wrist + 0.3 * (true_wrist - C0_W).normalized();
  c.people[8][1][0].px[kRWrist] = project(c.cams[1], false_wrist);
  c.people[8][1][0].confidence[kRWrist] = 0.95;
  const fs::path dir = writeDemo("outlier2", c);

  TriangulationReport report;
  const Skeleton s = triangulateDemo(dir.string(), captureRate(), &report);
  checkAgainstTruth(s, c.truth, kHalfMm, {{4, kRWrist}, {8, kRWrist}});
  CHECK(report.n_points_inconsistent == 1);
  CHECK(report.n_bone_rejections == 1);

  TriangulateOptions no_bones = captureRate();
  no_bones.check_bone_lengths = false;
  const Skeleton unchecked = triangulateDemo(dir.string(), no_bones);
  REQUIRE(unchecked[8].ok[kRWrist]);  // consistent rays, so geometry alone accepts it ...
  CHECK((unchecked[8].p_W[kRWrist] - false_wrist).norm() < kHalfMm);  // ... at the false place
  CHECK_FALSE(unchecked[4].ok[kRWrist]);
}

TEST_CASE("resampling 30 -> 10 Hz keeps sample times and missing marks; it interpolates between adjacent frames, never across absent ones") {
  Skeleton in;
  for (int k = 0; k <= 30; ++k) {
    SkeletonFrame f;
    f.t_s = k / 30.0;
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      f.p_W[static_cast<std::size_t>(i)] = Eigen::Vector3d(f.t_s, 2.0 * f.t_s + i, 3.0);
      f.ok[static_cast<std::size_t>(i)] = true;
    }
    in.push_back(f);
  }
  in[6].ok[3] = false;   // t = 0.2: a 10 Hz sample
  in[7].ok[4] = false;   // t = 0.2333: between 10 Hz samples, a neighbour of a 12 Hz sample
  const Skeleton out10 = resampleSkeleton(in, 10.0, 30.0);
  REQUIRE(out10.size() == 11);
  for (std::size_t j = 0; j < out10.size(); ++j) {
    CHECK(out10[j].t_s == static_cast<double>(j) / 10.0);
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      const bool expect_ok = !(j == 2 && i == 3);
      CHECK(out10[j].ok[i] == expect_ok);
      if (expect_ok) CHECK(out10[j].p_W[i] == in[3 * j].p_W[i]);
    }
  }
  const Skeleton out12 = resampleSkeleton(in, 12.0, 30.0);
  REQUIRE(out12.size() == 13);
  CHECK_FALSE(out12[3].ok[4]);  // t = 0.25 lies between frames 7 (missing) and 8: stays missing
  CHECK(out12[3].ok[3]);
  CHECK((out12[3].p_W[3] - Eigen::Vector3d(0.25, 3.5, 3.0)).norm() < 1e-12);  // linear motion, exact
  CHECK_THROWS_WITH_AS(resampleSkeleton(in, 0.0, 30.0), doctest::Contains("--rate must be"), UserError);
  CHECK_THROWS_WITH_AS(resampleSkeleton(in, 10.0, 0.0), doctest::Contains("--fps must be"), UserError);

  // Capture frames 10..12 absent (a gap in t_s): output times inside the gap, or between its
  // edges, have no capture sample on one side and stay missing; nothing is bridged.
  Skeleton gap;
  for (std::size_t k = 0; k < in.size(); ++k)
    if (k < 10 || k > 12) gap.push_back(in[k]);
  const Skeleton gap10 = resampleSkeleton(gap, 10.0, 30.0);
  REQUIRE(gap10.size() == 11);
  const Skeleton gap12 = resampleSkeleton(gap, 12.0, 30.0);
  REQUIRE(gap12.size() == 13);
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    CHECK_MESSAGE(!gap10[4].ok[i], "t = 0.4 s (absent frame 12) point " << i << " was invented");
    CHECK_MESSAGE(!gap12[4].ok[i], "t = 1/3 s (absent frame 10) point " << i << " was invented");
    CHECK_MESSAGE(!gap12[5].ok[i], "t = 5/12 s (between absent frame 12 and frame 13) point " << i << " was invented");
    CHECK(gap10[4].p_W[i] == Eigen::Vector3d::Zero());
    CHECK(gap10[3].ok[i]);                         // t = 0.3: frame 9, present
    CHECK(gap10[5].ok[i]);                         // t = 0.5: frame 15, present
    CHECK(gap10[5].p_W[i] == in[15].p_W[i]);
    CHECK(gap12[6].ok[i]);                         // t = 0.5: frame 15
  }
  CHECK(gap12[4].t_s == doctest::Approx(1.0 / 3.0));

  // Through the whole pipeline: default options give 10 Hz samples equal to capture frames 0, 3, ...
  const Capture c = subjectOnly(2, 31);
  const Skeleton s = triangulateDemo(writeDemo("rate10", c).string(), TriangulateOptions{});
  REQUIRE(s.size() == 11);
  for (std::size_t j = 0; j < s.size(); ++j) {
    CHECK(s[j].t_s == doctest::Approx(static_cast<double>(j) / 10.0));
    for (int i = 0; i < kNumSkeletonPoints; ++i) CHECK(error(s[j], c.truth[3 * j], i) < kHalfMm);
  }
}

TEST_CASE("noisy triangulation is deterministic: two runs give bitwise-equal skeletons") {
  Capture c = subjectOnly(3, 10);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 3.0);
  for (FramePeople& frame : c.people)
    for (std::vector<Person2d>& cam : frame)
      for (int i = 0; i < kNumSkeletonPoints; ++i) cam[0].px[i] += Eigen::Vector2d(noise(rng), noise(rng));
  const fs::path dir = writeDemo("determinism", c);
  const Skeleton a = triangulateDemo(dir.string(), captureRate());
  const Skeleton b = triangulateDemo(dir.string(), captureRate());
  REQUIRE(a.size() == b.size());
  for (std::size_t k = 0; k < a.size(); ++k)
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      CHECK(a[k].ok[i] == b[k].ok[i]);
      CHECK(a[k].p_W[i] == b[k].p_W[i]);
    }
}

TEST_CASE("an Anipose TOML calibration triangulates exactly like the JSON one") {
  const Capture c = subjectOnly(2, 5);
  const fs::path dir = writeDemo("toml", c);
  std::ostringstream toml;
  toml.precision(17);
  toml << "[metadata]\nadjusted = false\n";
  for (std::size_t i = 0; i < c.cams.size(); ++i) {
    const Camera& cam = c.cams[i];
    const Eigen::Vector3d r = rodriguesFromRotation(cam.R_CW);
    toml << "\n[cam_" << i << "]\nname = \"" << cam.name << "\"\nsize = [ " << cam.width << ", " << cam.height << ",]\n"
         << "matrix = [ [ " << cam.K(0, 0) << ", " << cam.K(0, 1) << ", " << cam.K(0, 2) << ",], [ 0.0, " << cam.K(1, 1)
         << ", " << cam.K(1, 2) << ",], [ 0.0, 0.0, 1.0,],]\ndistortions = [ " << cam.dist[0] << ", " << cam.dist[1]
         << ", " << cam.dist[2] << ", " << cam.dist[3] << ", " << cam.dist[4] << ",]\nrotation = [ " << r.x() << ", "
         << r.y() << ", " << r.z() << ",]\ntranslation = [ " << cam.p_CW.x() << ", " << cam.p_CW.y() << ", "
         << cam.p_CW.z() << ",]\n";
  }
  writeText(dir / "calibration.toml", toml.str());
  const std::vector<std::string> dirs = {(dir / "cam0").string(), (dir / "cam1").string()};
  const Skeleton from_toml = triangulateFolders(dirs, (dir / "calibration.toml").string(), captureRate());
  const Skeleton from_json = triangulateFolders(dirs, (dir / "calibration.json").string(), captureRate());
  checkAgainstTruth(from_toml, c.truth, kHalfMm);
  for (std::size_t k = 0; k < from_toml.size(); ++k)
    for (int i = 0; i < kNumSkeletonPoints; ++i) CHECK((from_toml[k].p_W[i] - from_json[k].p_W[i]).norm() < 1e-9);
}

TEST_CASE("input that cannot be triangulated gives one clear error") {
  const Capture c = subjectOnly(2, 4);
  const fs::path dir = writeDemo("errors", c);
  const std::string cam0 = (dir / "cam0").string(), cam1 = (dir / "cam1").string();
  const std::string calibration = (dir / "calibration.json").string();
  const TriangulateOptions opt;
  SUBCASE("camera count does not match folder count") {
    CHECK_THROWS_WITH_AS(triangulateFolders({cam0, cam1, cam0}, calibration, opt),
                         doctest::Contains("has 2 cameras but 3 keypoint folders were given"), UserError);
  }
  SUBCASE("one camera") {
    const fs::path one = dir / "one.json";
    writeText(one, formatCalibrationJson({c.cams[0]}));
    CHECK_THROWS_WITH_AS(triangulateFolders({cam0}, one.string(), opt), doctest::Contains("at least 2 cameras"), UserError);
  }
  SUBCASE("folders with different frame counts are not an error: frames pair by index") {
    fs::remove(dir / "cam1" / "errors_000000000003_keypoints.json");
    TriangulationReport report;
    const Skeleton s = triangulateFolders({cam0, cam1}, calibration, captureRate(), &report);
    REQUIRE(s.size() == 4);
    CHECK(report.n_frames_incomplete == 1);
    for (int i = 0; i < kNumSkeletonPoints; ++i) CHECK_FALSE(s[3].ok[i]);  // one view left: missing
    checkAgainstTruth({s.begin(), s.begin() + 3}, {c.truth.begin(), c.truth.begin() + 3}, kHalfMm);
  }
  SUBCASE("two frames with one index in a camera") {
    std::vector<CameraKeypoints> kp = {readOpenPoseFolder(cam0, PoseFormat::kBody25),
                                       readOpenPoseFolder(cam1, PoseFormat::kBody25)};
    kp[1].frames[2].index = 1;
    CHECK_THROWS_WITH_AS(triangulateCapture(c.cams, kp, opt), doctest::Contains("two files for frame 1"), UserError);
  }
  SUBCASE("frame indices spanning more than a day (a stray file)") {
    writeText(dir / "cam1" / "errors_009000000000_keypoints.json", formatOpenPoseJson(c.people[0][1], PoseFormat::kBody25));
    CHECK_THROWS_WITH_AS(triangulateFolders({cam0, cam1}, calibration, opt),
                         doctest::Contains("frame indices run from 0 to 9000000000"), UserError);
  }
  SUBCASE("nobody in any frame of a camera") {
    for (int k = 0; k < 4; ++k) {
      char file[64];
      std::snprintf(file, sizeof file, "errors_%012d_keypoints.json", k);
      writeText(dir / "cam1" / file, "{\"version\": 1.3, \"people\": []}");
    }
    CHECK_THROWS_WITH_AS(triangulateFolders({cam0, cam1}, calibration, opt),
                         doctest::Contains("no person detected in any of its 4 frames"), UserError);
  }
  SUBCASE("calibration that does not parse") {
    writeText(dir / "calibration.json", "{\"cameras\": [}");
    CHECK_THROWS_WITH_AS(triangulateDemo(dir.string(), opt), doctest::Contains("calibration JSON does not parse"), UserError);
  }
  SUBCASE("demo folder without cameras") {
    const fs::path empty = freshDir("errors_empty");
    CHECK_THROWS_WITH_AS(triangulateDemo(empty.string(), opt), doctest::Contains("no cam*/ keypoint folders"), UserError);
  }
}

TEST_CASE("frames absent from every camera keep their time: a gap in t_s, later frames at the right time") {
  const Capture c = subjectOnly(2, 12);
  const fs::path dir = writeDemo("gap_all", c, PoseFormat::kBody25, {{-1, 4}, {-1, 5}, {-1, 6}});
  const std::vector<std::string> dirs = demoCameraDirs(dir.string());
  const CameraSet cams = readCalibration((dir / "calibration.json").string());
  std::vector<CameraKeypoints> kp;
  for (const std::string& d : dirs) kp.push_back(readOpenPoseFolder(d, PoseFormat::kBody25));
  TriangulationReport report;
  std::vector<std::pair<int, int>> progress;
  TriangulateOptions opt = captureRate();
  opt.progress = [&](int done, int total) { progress.emplace_back(done, total); };
  const Skeleton capture = triangulateCapture(cams, kp, opt, &report);
  const std::vector<int> present = {0, 1, 2, 3, 7, 8, 9, 10, 11};
  REQUIRE(capture.size() == present.size());
  for (std::size_t j = 0; j < present.size(); ++j) {
    const int k = present[j];
    CHECK_MESSAGE(capture[j].t_s == doctest::Approx(k / 30.0),
                  "capture frame of file " << k << " stamped " << capture[j].t_s << " s, expected " << k / 30.0 << " s");
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      REQUIRE(capture[j].ok[i]);
      CHECK_MESSAGE(error(capture[j], c.truth[static_cast<std::size_t>(k)], i) < kHalfMm,
                    "file " << k << " point " << kSkeletonPointNames[i] << " does not match its own frame's truth");
    }
  }
  // The report spans the time the output covers: the absent frames count, with every point missing.
  CHECK(report.n_frames == 12);
  CHECK(report.n_frames_absent == 3);
  CHECK(report.n_frames_incomplete == 0);
  CHECK(report.n_frames_without_subject == 3);
  CHECK(report.n_points_valid == 9 * kNumSkeletonPoints);
  CHECK(report.n_points_missing == 3 * kNumSkeletonPoints);
  REQUIRE(progress.size() == 9);
  CHECK(progress.back() == std::make_pair(9, 9));

  // Resampled at the capture rate: a row for every 1/30 s, the absent frames' rows missing.
  std::vector<std::pair<int, int>> missing;
  for (int k = 4; k <= 6; ++k)
    for (int i = 0; i < kNumSkeletonPoints; ++i) missing.emplace_back(k, i);
  checkAgainstTruth(triangulateDemo(dir.string(), captureRate()), c.truth, kHalfMm, missing);
  // At 12 Hz: t = 1/12 s lies between frames 2 and 3 (interpolated), t = 1/6 s is frame 5 (absent).
  TriangulateOptions at12 = captureRate();
  at12.rate_hz = 12.0;
  const Skeleton s12 = triangulateDemo(dir.string(), at12);
  REQUIRE(s12.size() == 5);
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    CHECK(s12[1].ok[i]);
    CHECK_MESSAGE(!s12[2].ok[i], "t = 1/6 s (absent frame 5) point " << kSkeletonPointNames[i] << " was invented");
  }
}

TEST_CASE("a frame file missing in one camera does not shift the pairing of later frames (2 cameras)") {
  // cam1 lacks frame 3 and cam0 lacks frame 8: both folders hold 11 files, yet frame k of one
  // camera must still pair with frame k of the other. Frames 3 and 8 have one view: missing.
  const Capture c = subjectOnly(2, 12);
  const fs::path dir = writeDemo("gap_one", c, PoseFormat::kBody25, {{1, 3}, {0, 8}});
  TriangulationReport report;
  const Skeleton s = triangulateDemo(dir.string(), captureRate(), &report);
  std::vector<std::pair<int, int>> missing;
  for (int k : {3, 8})
    for (int i = 0; i < kNumSkeletonPoints; ++i) missing.emplace_back(k, i);
  checkAgainstTruth(s, c.truth, kHalfMm, missing);
  CHECK(report.n_frames == 12);
  CHECK(report.n_frames_incomplete == 2);
  CHECK(report.n_frames_without_subject == 2);
  CHECK(report.n_frames_absent == 0);
}

TEST_CASE("three cameras: a frame missing in one camera still triangulates from the other two") {
  const Capture c = subjectOnly(3, 10);
  const fs::path dir = writeDemo("gap_three", c, PoseFormat::kBody25, {{2, 4}, {0, 7}});
  TriangulationReport report;
  const Skeleton s = triangulateDemo(dir.string(), captureRate(), &report);
  // A point is expected only where the cameras that have the frame give >= 2 views of it.
  std::vector<std::pair<int, int>> missing;
  for (int k = 0; k < 10; ++k)
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      int views = 0;
      for (int cam = 0; cam < 3; ++cam)
        if (!(cam == 2 && k == 4) && !(cam == 0 && k == 7) && c.people[static_cast<std::size_t>(k)][static_cast<std::size_t>(cam)][0].detected(i))
          ++views;
      if (views < 2) missing.emplace_back(k, i);
    }
  MESSAGE(missing.size() << " points with fewer than 2 views in the frames left");
  CHECK(missing.size() < 4);  // the scene: nearly every point is seen by every camera
  checkAgainstTruth(s, c.truth, kHalfMm, missing);
  CHECK(report.n_frames_incomplete == 2);
  CHECK(report.n_frames_without_subject == 0);
}

TEST_CASE("the refinement never ends behind a camera it started in front of, nor at a higher cost") {
  // A point 2-3 cm in front of camera 0 seen with ~20 px errors: Levenberg-Marquardt steps can
  // cross camera 0's plane. ceres::TinySolver ignores a false return of the cost functor and
  // goes on with stale residuals, so it used to accept such a step and end ~1 m behind camera 0.
  // The cases below were found by a seeded random search (200000 trials, 303 such failures).
  CameraSet cams(2);
  for (Camera& cam : cams) {
    cam.width = 1920, cam.height = 1080;
    cam.K << 900.0, 0.0, 960.0, 0.0, 900.0, 540.0, 0.0, 0.0, 1.0;
    cam.dist.setZero();
  }
  cams[0].R_CW.setIdentity();
  cams[0].p_CW.setZero();
  const Eigen::Vector3d C1_W(1.5, 0.0, 0.2);
  const Eigen::Vector3d z = (Eigen::Vector3d(0.0, 0.0, 0.5) - C1_W).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitY()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  cams[1].R_CW.row(0) = x.transpose(), cams[1].R_CW.row(1) = y.transpose(), cams[1].R_CW.row(2) = z.transpose();
  cams[1].p_CW = -cams[1].R_CW * C1_W;

  struct Case {
    Eigen::Vector3d p0_W;
    Eigen::Vector2d px0, px1;
  };
  const std::vector<Case> cases = {
      {{-0.0096919405447192693, -0.0074741903243963738, 0.030287673603811387},
       {846.77592961407242, 199.45728258021711},
       {1269.4404418938345, 529.72421311036453}},
      {{0.0066542099714726761, -0.0062825654529661884, 0.030040059690702968},
       {1338.4171232265383, 186.26974093740665},
       {1270.7864774504815, 544.84052773216706}}};
  for (const Case& k : cases) {
    const std::vector<Observation> obs = {{0, k.px0, 1.0}, {1, k.px1, 1.0}};
    const auto cost = [&](const Eigen::Vector3d& p_W) {
      double sum = 0.0;
      for (const Observation& o : obs) {
        const Camera& cam = cams[static_cast<std::size_t>(o.camera)];
        if (toCamera(cam, p_W).z() <= 0.0) return std::numeric_limits<double>::infinity();
        sum += (project(cam, p_W) - o.px).squaredNorm();
      }
      return sum;
    };
    REQUIRE(toCamera(cams[0], k.p0_W).z() > 0.0);
    REQUIRE(toCamera(cams[1], k.p0_W).z() > 0.0);
    const Eigen::Vector3d p_W = refineOnReprojection(cams, obs, k.p0_W, 30);
    CHECK_MESSAGE(toCamera(cams[0], p_W).z() > 0.0,
                  "refined point " << p_W.transpose() << " is behind camera 0 (depth " << toCamera(cams[0], p_W).z() << " m)");
    CHECK_MESSAGE(cost(p_W) <= cost(k.p0_W), "cost rose from " << cost(k.p0_W) << " to " << cost(p_W) << " px^2");
  }
}

namespace {

// Four cameras: the two front ones, the high one, and a low one on the subject's right.
CameraSet fourCameras() {
  CameraSet cams = cameras(3);
  Eigen::Matrix<double, 5, 1> d3;
  d3 << -0.03, 0.005, 0.0001, 0.0002, 0.0;
  cams.push_back(lookAt("cam3", {1.2, -3.0, 0.7}, {0.0, 0.0, 1.0}, 920.0, d3));
  return cams;
}

}  // namespace

TEST_CASE("four cameras: with two wrong views (a swap and a confident outlier) the two that agree make the point") {
  const CameraSet cams = fourCameras();
  const Points p = body(0.4);
  std::vector<Observation> obs;
  for (int c = 0; c < 4; ++c) obs.push_back({c, project(cams[static_cast<std::size_t>(c)], p[kRWrist]), 0.8});
  obs[1].px = project(cams[1], p[kLWrist]);  // left/right swap in cam1
  obs[1].confidence = 0.95;
  obs[2].px += Eigen::Vector2d(60.0, -25.0);  // confident wrong keypoint in cam2
  obs[2].confidence = 0.97;
  const PointEstimate est = triangulatePoint(cams, obs, TriangulateOptions{});
  REQUIRE(est.ok);
  CHECK((est.p_W - p[kRWrist]).norm() < kHalfMm);
  CHECK(est.views == 0b1001u);
  CHECK(est.n_used == 2);
  CHECK(est.n_rejected == 2);
  CHECK(est.rms_px < 1e-3);
  // All four agreeing: every camera is used.
  obs[1].px = project(cams[1], p[kRWrist]);
  obs[2].px = project(cams[2], p[kRWrist]);
  const PointEstimate all = triangulatePoint(cams, obs, TriangulateOptions{});
  REQUIRE(all.ok);
  CHECK(all.views == 0b1111u);
  CHECK(all.n_rejected == 0);
}

TEST_CASE("the reprojection tolerance is given for 1080p and scales up with the image diagonal") {
  CameraSet cams = cameras(2);
  const Points p = body(0.2);
  // The two rays miss each other by ~24 px: each camera ~12 px off after the fit.
  const std::vector<Observation> obs = {{0, project(cams[0], p[kRElbow]), 0.9},
                                        {1, project(cams[1], p[kRElbow]) + Eigen::Vector2d(0.0, 24.0), 0.9}};
  const PointEstimate hd = triangulatePoint(cams, obs, TriangulateOptions{});
  CHECK_FALSE(hd.ok);
  CHECK(hd.inconsistent);
  for (Camera& c : cams) c.width = 3840, c.height = 2160;  // same pixels, twice the image: 20 px tolerance
  const PointEstimate uhd = triangulatePoint(cams, obs, TriangulateOptions{});
  REQUIRE(uhd.ok);
  CHECK(uhd.views == 0b11u);
  CHECK(uhd.rms_px > 10.0);
  CHECK(uhd.rms_px < 14.0);
  for (Camera& c : cams) c.width = 640, c.height = 480;  // smaller images keep the 1080p tolerance
  CHECK_FALSE(triangulatePoint(cams, obs, TriangulateOptions{}).ok);
}

TEST_CASE("gap policy: gaps up to max_gap_s are interpolated and flagged, longer ones and absent frames stay missing") {
  Capture c = subjectOnly(2, 40);
  for (int k = 5; k <= 10; ++k) c.people[static_cast<std::size_t>(k)][1][0].confidence[kRElbow] = 0.0;  // 6 frames = 0.2 s
  for (int k = 14; k <= 20; ++k) c.people[static_cast<std::size_t>(k)][0][0].confidence[kRWrist] = 0.0;  // 7 frames
  c.people[26][0][0].confidence[kLWrist] = 0.0;  // frame 27 absent from every camera, then 28 missing
  c.people[28][1][0].confidence[kLWrist] = 0.0;
  const fs::path dir = writeDemo("gaps", c, PoseFormat::kBody25, {{-1, 27}});
  TriangulateOptions opt = captureRate();
  opt.max_gap_s = 0.2;
  TriangulationReport report;
  const Skeleton s = triangulateDemo(dir.string(), opt, &report);
  REQUIRE(s.size() == 40);  // frame 27 is a gap in time: resampled as missing
  for (int k = 5; k <= 10; ++k) {
    const SkeletonFrame& f = s[static_cast<std::size_t>(k)];
    REQUIRE(f.ok[kRElbow]);
    CHECK(f.interpolated[kRElbow]);
    CHECK(f.views[kRElbow] == 0u);
    CHECK(error(f, c.truth[static_cast<std::size_t>(k)], kRElbow) < 0.01);
  }
  CHECK_FALSE(s[4].interpolated[kRElbow]);
  CHECK(s[4].views[kRElbow] == 0b11u);
  CHECK(s[4].reprojection_px[kRElbow] < 1e-3f);
  for (int k = 14; k <= 20; ++k) CHECK_FALSE(s[static_cast<std::size_t>(k)].ok[kRWrist]);
  for (int k : {26, 27, 28}) CHECK_FALSE(s[static_cast<std::size_t>(k)].ok[kLWrist]);
  CHECK(report.n_points_interpolated == 6);
  CHECK(report.n_points_valid + report.n_points_missing + report.n_points_interpolated == 40 * kNumSkeletonPoints);

  // Off: the same gap stays missing.
  opt.max_gap_s = 0.0;
  CHECK_FALSE(triangulateDemo(dir.string(), opt)[7].ok[kRElbow]);

  // The CSV writes interpolated points with _ok = 2 and reads them back as such.
  const fs::path csv = dir / "skeleton.csv";
  writeSkeletonCsv(csv.string(), s, true);
  const Skeleton back = readSkeletonCsv(csv.string());
  REQUIRE(back.size() == s.size());
  CHECK(back[7].ok[kRElbow]);
  CHECK(back[7].interpolated[kRElbow]);
  CHECK_FALSE(back[4].interpolated[kRElbow]);
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  CHECK(header.find(",RElbow_ok,") != std::string::npos);
  CHECK(header.find(",RElbow_cams,") != std::string::npos);
  CHECK(header.find(",RElbow_px,") != std::string::npos);
}
