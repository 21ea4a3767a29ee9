// Triangulation of 4-camera stress recordings (synth_stress.hpp: a crossing person, swaps, wrong
// keypoints, dropouts) and the clean-up after it: the zero-lag low-pass, the arm's bone fit, and
// what both do to the elbow angle and forearm lengths against the plain triangulation.
#include "nao/human_kinematics.hpp"
#include "nao/tools/synth_stress.hpp"
#include "nao/tools/triangulate.hpp"
#include "support/triangulation_scene.hpp"

#include <doctest/doctest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace {

using namespace nao;
using namespace nao::tools;
using namespace nao::test;

}  // namespace

TEST_CASE("4-camera stress recordings: the right arm is kept through a crossing person, swaps, wrong keypoints and dropouts") {
  constexpr std::array<int, 3> kArm = {kRShoulder, kRElbow, kRWrist};
  int n_frames = 0, n_arm_valid = 0, n_wrong_view_points = 0, n_points = 0;
  int n_swapped = 0, n_wrong = 0, n_hidden = 0;
  std::vector<double> errors, baseline_errors;
  for (int m = 0; m < 3; ++m) {
    const SynthDemo demo = generateDemo(static_cast<Movement>(m), 0, 4242, false);
    StressOptions so;
    so.seed = 7 + static_cast<std::uint64_t>(m);
    const StressScene scene = renderStressScene(demo, so);
    TriangulateOptions opt;
    opt.fps = scene.fps;
    opt.rate_hz = scene.fps;
    opt.max_gap_s = 0.0;  // the consensus alone, no interpolation
    TriangulationReport report;
    const Skeleton s = triangulateCapture(scene.cameras, scene.keypoints, opt, &report);
    REQUIRE(s.size() == scene.truth.size());
    REQUIRE(report.subject_person.size() == s.size());
    // The baseline: every detection of the chosen people, no camera selection.
    TriangulateOptions all_views = opt;
    all_views.outlier_px = 1e9;
    const Skeleton b = triangulateCapture(scene.cameras, scene.keypoints, all_views);
    for (std::size_t k = 0; k < s.size(); ++k) {
      ++n_frames;
      bool arm = true;
      for (int i : kArm) {
        // The scene keeps its promise: >= 2 correct views of every arm point.
        REQUIRE(__builtin_popcount(scene.correct_views[k][static_cast<std::size_t>(i)]) >= 2);
        arm = arm && s[k].ok[i];
        if (b[k].ok[i]) baseline_errors.push_back((b[k].p_W[i] - scene.truth[k].p_W[i]).norm());
        if (!s[k].ok[i]) continue;
        errors.push_back((s[k].p_W[i] - scene.truth[k].p_W[i]).norm());
        ++n_points;
        if ((s[k].views[i] & ~scene.correct_views[k][static_cast<std::size_t>(i)]) != 0u) ++n_wrong_view_points;
      }
      n_arm_valid += arm ? 1 : 0;
      for (std::size_t c = 0; c < scene.cameras.size(); ++c) {
        // Never the second person: each camera contributes the subject's detection or nothing.
        const int chosen = report.subject_person[k][c];
        CHECK_MESSAGE((chosen < 0 || chosen == scene.subject_index[k][c]),
                      "movement " << m << " frame " << k << " camera " << c << " used person " << chosen
                                  << ", the subject is " << scene.subject_index[k][c]);
      }
    }
    n_hidden += scene.n_hidden_points;
    MESSAGE(std::string(kMovementNames[static_cast<std::size_t>(m)]) << ": frames without subject " << report.n_frames_without_subject
                                                        << ", inconsistent points " << report.n_points_inconsistent
                                                        << ", bone-length rejections " << report.n_bone_rejections);
    n_swapped += scene.n_swapped_frames;
    n_wrong += scene.n_wrong_keypoints;
  }
  const double arm_rate = static_cast<double>(n_arm_valid) / n_frames;
  MESSAGE("right arm valid in " << n_arm_valid << "/" << n_frames << " frames (" << 100.0 * arm_rate << " %); arm points "
                                << n_points << ", median error " << quantile(errors, 0.5) * 1e3 << " mm, p95 "
                                << quantile(errors, 0.95) * 1e3 << " mm; baseline (all views) p95 "
                                << quantile(baseline_errors, 0.95) * 1e3 << " mm; frames with swapped arms " << n_swapped
                                << ", wrong confident keypoints " << n_wrong << ", subject points hidden by the second person "
                                << n_hidden << "; points fitted with a wrong view " << n_wrong_view_points);
  // The faults are really there.
  CHECK(n_swapped > 100);
  CHECK(n_wrong > 100);
  CHECK(n_hidden > 100);
  CHECK(quantile(baseline_errors, 0.95) > 0.03);
  // The triangulation targets.
  CHECK(arm_rate >= 0.98);
  CHECK(quantile(errors, 0.5) <= 0.01);
  CHECK(quantile(errors, 0.95) <= 0.03);
  // Left: a left/right swap whose wrong arm lies on the epipolar plane of the one other camera
  // that sees it, a tie of two camera pairs that continuity does not always break right.
  CHECK(n_wrong_view_points <= n_points / 200);
}

namespace {

struct ArmScore {
  std::vector<double> elbow_deg;  // |elbow flexion - truth's| per frame with the arm valid
  int n_frames = 0, n_arm = 0, n_forearm = 0, n_out_of_band = 0;
};

void scoreArm(const Skeleton& s, const Skeleton& truth, ArmScore& score) {
  HumanArmData est, ref;
  for (std::size_t k = 0; k < s.size(); ++k) {
    ++score.n_frames;
    score.n_arm += (s[k].ok[kRShoulder] && s[k].ok[kRElbow] && s[k].ok[kRWrist]) ? 1 : 0;
    if (s[k].ok[kRElbow] && s[k].ok[kRWrist]) {
      const double l = (s[k].p_W[kRWrist] - s[k].p_W[kRElbow]).norm();
      ++score.n_forearm;
      score.n_out_of_band += (l < 0.20 || l > 0.32) ? 1 : 0;
    }
    humanArmKinematics(HumanKinematicsConfig{}, est, s[k]);
    humanArmKinematics(HumanKinematicsConfig{}, ref, truth[k]);
    if (est.valid && ref.valid)
      score.elbow_deg.push_back(std::abs(est.q[kHumanElbowRoll] - ref.q[kHumanElbowRoll]) * 180.0 / 3.14159265358979323846);
  }
}

}  // namespace

TEST_CASE("zero-lag smoothing keeps a steady motion exactly, even at the ends of a run, and never crosses an absent frame") {
  Skeleton s;
  for (int k = 0; k < 40; ++k) {
    if (k == 20 || k == 21) continue;  // absent frame indices: two runs
    SkeletonFrame f;
    f.t_s = k / 60.0;
    f.p_W.fill(Eigen::Vector3d::Zero());
    f.ok.fill(false);
    f.ok[kRWrist] = true;
    // A steady motion, with a 10 cm step between the runs.
    f.p_W[kRWrist] = Eigen::Vector3d(0.5 * f.t_s, -0.2 * f.t_s, 1.0 + (k > 21 ? 0.1 : 0.0));
    s.push_back(f);
  }
  const Skeleton raw = s;
  CHECK(smoothSkeletonZeroLag(s, 0.05, 60.0) == static_cast<int>(s.size()));
  double worst = 0.0;
  for (std::size_t k = 0; k < s.size(); ++k) worst = std::max(worst, (s[k].p_W[kRWrist] - raw[k].p_W[kRWrist]).norm());
  CHECK(worst < 1e-12);
}

TEST_CASE("zero-lag smoothing of white noise leaves about 1 / sqrt(2 sqrt(pi) sigma fps) of it") {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.01);
  Skeleton s;
  for (int k = 0; k < 3000; ++k) {
    SkeletonFrame f;
    f.t_s = k / 60.0;
    f.p_W.fill(Eigen::Vector3d::Zero());
    f.ok.fill(false);
    f.ok[kRElbow] = true;
    f.p_W[kRElbow] = Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    s.push_back(f);
  }
  smoothSkeletonZeroLag(s, 0.05, 60.0);
  double sum2 = 0.0;
  int n = 0;
  for (std::size_t k = 100; k + 100 < s.size(); ++k, ++n) sum2 += s[k].p_W[kRElbow].squaredNorm() / 3.0;
  const double ratio = std::sqrt(sum2 / n) / 0.01;
  // Interior points: a Gaussian kernel of sigma * fps = 3 samples averages 2 sqrt(pi) 3 = 10.6 of them.
  const double expected = 1.0 / std::sqrt(2.0 * std::sqrt(3.14159265358979323846) * 3.0);
  MESSAGE("noise left: " << ratio << " (expected " << expected << ")");
  CHECK(ratio == doctest::Approx(expected).epsilon(0.1));
}

TEST_CASE("the arm's bone fit moves noisy two-camera points towards the truth and their bones to the reference") {
  const Capture c = subjectOnly(2, 120, false);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> px_noise(0.0, 3.0);
  BoneLengths bones;
  for (std::size_t b = 0; b < kSkeletonBones.size(); ++b) {
    const auto [i, j] = kSkeletonBones[b];
    bones.median_m[b] = (c.truth[0][static_cast<std::size_t>(i)] - c.truth[0][static_cast<std::size_t>(j)]).norm();
    bones.checked[b] = true;
  }
  double error_before = 0.0, error_after = 0.0, bone_before = 0.0, bone_after = 0.0;
  int n_fits = 0;
  TriangulationState state;
  for (std::size_t k = 0; k < c.people.size(); ++k) {
    FramePeople people = c.people[k];
    for (auto& cam : people)
      for (Person2d& p : cam)
        for (int i = 0; i < kNumSkeletonPoints; ++i)
          if (p.detected(i)) p.px[i] += Eigen::Vector2d(px_noise(rng), px_noise(rng));
    std::vector<const std::vector<Person2d>*> ptrs;
    for (const auto& cam : people) ptrs.push_back(&cam);
    SkeletonFrame f;
    const FrameTriangulation done =
        triangulateFrame(c.cams, ptrs, static_cast<double>(k) / 30.0, TriangulationParams{}, state, f);
    REQUIRE(done.subject.found);
    const SkeletonFrame before = f;
    const FrameObservations obs{&c.cams, &ptrs, &done.subject.person};
    if (!fitArmBoneLengths(obs, bones, 300.0, 30, f)) continue;
    ++n_fits;
    const auto arm_error = [&](const SkeletonFrame& s) {
      return (s.p_W[kRElbow] - c.truth[k][kRElbow]).norm() + (s.p_W[kRWrist] - c.truth[k][kRWrist]).norm();
    };
    const auto bone_error = [&](const SkeletonFrame& s) {
      return std::abs((s.p_W[kRElbow] - s.p_W[kRShoulder]).norm() - bones.median_m[4]) +
             std::abs((s.p_W[kRWrist] - s.p_W[kRElbow]).norm() - bones.median_m[5]);
    };
    error_before += arm_error(before), error_after += arm_error(f);
    bone_before += bone_error(before), bone_after += bone_error(f);
    for (int i = 0; i < kNumSkeletonPoints; ++i)
      if (i != kRShoulder && i != kRElbow && i != kRWrist) CHECK(f.p_W[i] == before.p_W[i]);  // only the arm moves
  }
  MESSAGE("fits " << n_fits << "; mean elbow+wrist error " << 1e3 * error_before / n_fits << " -> " << 1e3 * error_after / n_fits
                  << " mm; mean bone-length error " << 1e3 * bone_before / n_fits << " -> " << 1e3 * bone_after / n_fits << " mm");
  CHECK(n_fits == 120);
  CHECK(bone_after < 0.5 * bone_before);
  CHECK(error_after < 0.9 * error_before);
}

TEST_CASE("on stress recordings with a confidence-telling detector, smoothing and the bone fit halve the elbow error, keep forearms in the adult band and lose no arm frame") {
  ArmScore plain, improved;
  for (int m = 0; m < 3; ++m) {
    const SynthDemo demo = generateDemo(static_cast<Movement>(m), 1, 4242, false);
    StressOptions so;
    so.seed = 21 + static_cast<std::uint64_t>(m);
    so.n_frames = 360;
    StressScene scene = renderStressScene(demo, so);
    addDetectorNoise(scene, 77 + static_cast<std::uint64_t>(m));
    TriangulateOptions opt;
    opt.fps = scene.fps;
    opt.rate_hz = scene.fps;
    scoreArm(triangulateCapture(scene.cameras, scene.keypoints, opt), scene.truth, plain);
    opt.zero_lag_sigma_s = 0.05;   // nao_toolchain triangulate's --smooth
    opt.bone_fit_px_per_m = 300.0;  // ... and --bone-fit
    scoreArm(triangulateCapture(scene.cameras, scene.keypoints, opt), scene.truth, improved);
  }
  const auto band = [](const ArmScore& s) { return static_cast<double>(s.n_out_of_band) / s.n_forearm; };
  MESSAGE("elbow flexion error median " << quantile(plain.elbow_deg, 0.5) << " -> " << quantile(improved.elbow_deg, 0.5)
                                        << " deg, p95 " << quantile(plain.elbow_deg, 0.95) << " -> "
                                        << quantile(improved.elbow_deg, 0.95) << " deg; forearms outside 0.20-0.32 m "
                                        << 100.0 * band(plain) << " -> " << 100.0 * band(improved) << " %");
  CHECK(quantile(improved.elbow_deg, 0.5) < 0.5 * quantile(plain.elbow_deg, 0.5));
  CHECK(quantile(improved.elbow_deg, 0.95) < 0.5 * quantile(plain.elbow_deg, 0.95));
  CHECK(band(plain) > 0.01);  // the noise really throws forearms out of the band
  CHECK(band(improved) < 0.25 * band(plain));
  CHECK(improved.n_arm == plain.n_arm);  // not one arm frame lost to the fit or the smoothing
  CHECK(improved.n_arm >= improved.n_frames - improved.n_frames / 200);
}
