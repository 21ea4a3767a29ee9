// Retargeting (paper Algorithm 1): reach, limits, joint priority, determinism, and the online
// fixed-size LM cross-checked against the offline Ceres version on the same frames.
#include "nao/retarget.hpp"
#include "nao/tools/retarget_ceres.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

using namespace nao;
using nao::tools::RetargetFrame;

namespace {

constexpr double kTickS = 0.1;  // 10 Hz, the runtime's rate

const ArmModel& arm() {
  static const ArmModel model = loadArmModel(nao::test::kUrdfPath);
  return model;
}

// A smooth joint-space path inside the limits: per joint, the middle of the range plus two
// sines of random frequency (0.3-1.5 rad/s) and phase with a peak of 45 % of the range, so
// every pose stays inside the limits.
std::vector<JointVector> smoothPath(const ArmModel& m, std::mt19937_64& rng, int n_frames) {
  std::uniform_real_distribution<double> freq(0.3, 1.5), phase(0.0, 6.283185307179586), mix(0.3, 0.7);
  JointVector w1, w2, p1, p2, a;
  for (int j = 0; j < kNumJoints; ++j) {
    w1[j] = freq(rng);
    w2[j] = freq(rng);
    p1[j] = phase(rng);
    p2[j] = phase(rng);
    a[j] = mix(rng);
  }
  std::vector<JointVector> path;
  for (int k = 0; k < n_frames; ++k) {
    const double t = k * kTickS;
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j) {
      const double mid = 0.5 * (m.q_min[j] + m.q_max[j]);
      const double range = m.q_max[j] - m.q_min[j];
      q[j] = mid + 0.45 * range * (a[j] * std::sin(w1[j] * t + p1[j]) + (1.0 - a[j]) * std::sin(w2[j] * t + p2[j]));
    }
    path.push_back(q);
  }
  return path;
}

// Frames whose hand target is FK of the path (reachable by construction) and whose joint
// target is the path plus a smooth offset of up to ~0.45 rad per joint (the embodiment gap:
// the human's angles do not put NAO's hand where the scaled human hand is). The joint target
// may leave the limits.
std::vector<RetargetFrame> trajectoryFrames(const ArmModel& m, std::mt19937_64& rng, int n_frames,
                                            bool with_pointing) {
  const std::vector<JointVector> path = smoothPath(m, rng, n_frames);
  std::uniform_real_distribution<double> offset(-0.3, 0.3), wobble(0.0, 0.15), freq(0.5, 2.0);
  JointVector c, amp, w;
  for (int j = 0; j < kNumJoints; ++j) {
    c[j] = offset(rng);
    amp[j] = wobble(rng);
    w[j] = freq(rng);
  }
  ArmData d;
  std::vector<RetargetFrame> frames;
  for (int k = 0; k < n_frames; ++k) {
    RetargetFrame f;
    f.p_target_TH = forwardKinematics(m, d, path[k]);
    f.has_pointing = with_pointing;
    f.u_target_TH = d.u_TH;
    for (int j = 0; j < kNumJoints; ++j) f.q_target[j] = path[k][j] + c[j] + amp[j] * std::sin(w[j] * k * kTickS);
    frames.push_back(f);
  }
  return frames;
}

bool insideLimits(const ArmModel& m, const JointVector& q) {
  return (q.array() >= m.q_min.array()).all() && (q.array() <= m.q_max.array()).all();
}

}  // namespace

TEST_CASE("q_x reaches every target of 20 warm-started smooth trajectories within 1 mm") {
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(101);
  double worst = 0.0;
  int n_frames = 0, n_flagged_x = 0;
  for (int traj = 0; traj < 20; ++traj) {
    RetargetData data;
    for (const RetargetFrame& f : trajectoryFrames(m, rng, 100, false)) {
      const RetargetResult& r = solveRetarget(m, params, data, f.p_target_TH, f.q_target);
      worst = std::max(worst, r.error_x_m);
      n_flagged_x += (r.flags & (kRetargetXCapHit | kRetargetXUnreachable)) != 0;
      ++n_frames;
    }
  }
  MESSAGE("largest q_x hand error over " << n_frames << " frames: " << worst * 1e3 << " mm");
  CHECK_MESSAGE(worst < 1e-3, "expected every hand error < 1 mm, got a largest error of " << worst * 1e3 << " mm");
  CHECK_MESSAGE(n_flagged_x == 0, "expected no q_x cap/unreachable flags, got " << n_flagged_x);
}

TEST_CASE("q_x reaches a reachable target from an unrelated random start in at least 85 % of 2000 cases") {
  // Far starts (a random pose to another random pose) can end in a local minimum against a
  // joint limit: measured 88.5 % success with this seed; the bound guards against regressions.
  // The warm-started case above is the one the runtime depends on and is asserted fully.
  const ArmModel& m = arm();
  const RetargetParams params;
  RetargetData data;
  ArmData d;
  std::mt19937_64 rng(202);
  int n_ok = 0;
  constexpr int kCases = 2000;
  for (int i = 0; i < kCases; ++i) {
    const Eigen::Vector3d target = forwardKinematics(m, d, nao::test::randomPose(m, rng));
    const JointVector start = nao::test::randomPose(m, rng);
    const JointVector& q = solveHandIk(m, params, data, target, start, start);
    n_ok += (forwardKinematics(m, d, q) - target).norm() < 1e-3;
  }
  const double rate = static_cast<double>(n_ok) / kCases;
  MESSAGE("far-start success rate (hand error < 1 mm): " << 100.0 * rate << " %");
  CHECK_MESSAGE(rate >= 0.85, "expected >= 85 % of far starts within 1 mm, got " << 100.0 * rate << " %");
}

// NAO has no wrist pitch: RWristYaw turns about the hand's own x axis, so it cannot change
// the pointing direction and moves the hand point only through the 1.2 cm HandOffsetZ lever.
// Position (3) and direction (2) are then served by effectively four joints, and the
// weighted solve can settle with RWristYaw on a limit and a small residual in both. The claim
// is therefore a trade-off, measured against solving the same frames position-only.
TEST_CASE("a pointing target turns the hand toward it at a cost of at most 5 mm of hand position") {
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(303);
  ArmData d;
  std::vector<double> err_mm, deg_with, deg_without;
  for (int traj = 0; traj < 10; ++traj) {
    RetargetData with, without;
    for (const RetargetFrame& f : trajectoryFrames(m, rng, 100, true)) {
      forwardKinematics(m, d, solveRetarget(m, params, with, f.p_target_TH, f.q_target, &f.u_target_TH).q_x);
      err_mm.push_back((d.p_TH - f.p_target_TH).norm() * 1e3);
      deg_with.push_back(std::acos(std::clamp(d.u_TH.dot(f.u_target_TH), -1.0, 1.0)) / nao::test::kDeg);
      forwardKinematics(m, d, solveRetarget(m, params, without, f.p_target_TH, f.q_target).q_x);
      deg_without.push_back(std::acos(std::clamp(d.u_TH.dot(f.u_target_TH), -1.0, 1.0)) / nao::test::kDeg);
    }
  }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  const double worst_mm = *std::max_element(err_mm.begin(), err_mm.end());
  const double worst_deg = *std::max_element(deg_with.begin(), deg_with.end());
  MESSAGE("with pointing: median " << median(err_mm) << " mm / " << median(deg_with) << " deg, worst " << worst_mm
                                   << " mm / " << worst_deg << " deg; position-only: median " << median(deg_without)
                                   << " deg");
  CHECK_MESSAGE(worst_mm < 5.0, "expected hand error < 5 mm with a pointing target, got " << worst_mm << " mm");
  CHECK_MESSAGE(median(deg_with) < 1.0, "expected median direction error < 1 deg, got " << median(deg_with));
  CHECK_MESSAGE(median(deg_with) < 0.25 * median(deg_without),
                "the pointing target should cut the median direction error at least fourfold: " << median(deg_with)
                                                                                               << " vs "
                                                                                               << median(deg_without));
}

TEST_CASE("retarget keeps every output joint inside its URDF limits, also for unreachable targets and joint targets outside the limits") {
  const ArmModel& m = arm();
  const RetargetParams params;
  RetargetData data;
  nao::tools::CeresRetargetData ceres_data;
  std::mt19937_64 rng(404);
  // Hand targets anywhere in a 1.2 m cube around the shoulder (most unreachable: the arm is
  // ~0.22 m long), joint targets up to twice the range beyond the limits.
  std::uniform_real_distribution<double> box(-0.6, 0.6), unit(-1.0, 1.0);
  int n_outside = 0, n_unreachable_flagged = 0;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d target(box(rng), -0.098 + box(rng), 0.1 + box(rng));
    JointVector q_target;
    for (int j = 0; j < kNumJoints; ++j) {
      const double mid = 0.5 * (m.q_min[j] + m.q_max[j]);
      q_target[j] = mid + 2.0 * (m.q_max[j] - m.q_min[j]) * unit(rng);
    }
    const Eigen::Vector3d u(unit(rng), unit(rng), unit(rng));
    const bool pointing = i % 3 == 0;
    const RetargetResult& r = solveRetarget(m, params, data, target, q_target, pointing ? &u : nullptr);
    n_outside += !insideLimits(m, r.q_x) + !insideLimits(m, r.q_q);
    n_unreachable_flagged += (r.flags & kRetargetXUnreachable) != 0;
    if (i % 10 == 0) {
      const RetargetResult& rc = solveRetargetCeres(m, params, ceres_data, target, q_target, pointing ? &u : nullptr);
      n_outside += !insideLimits(m, rc.q_x) + !insideLimits(m, rc.q_q);
    }
  }
  CHECK_MESSAGE(n_outside == 0, "expected no pose outside the limits, got " << n_outside);
  // Most of the cube is out of reach: the flag must say so rather than pretend convergence.
  CHECK_MESSAGE(n_unreachable_flagged > 2000, "expected most targets flagged unreachable, got " << n_unreachable_flagged);
}

TEST_CASE("q_q moves the joints to q_target clamped to the limits: mean distance below 1 % of q_x's on 20 trajectories") {
  // With every IK anchored at the joint target, the outer loop's fixed point is q_target
  // clamped (see retarget.hpp): q_q should sit on it, q_x only as close as the hand target allows.
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(505);
  double sum_x = 0.0, sum_q = 0.0;
  int n_frames = 0, n_closer = 0;
  for (int traj = 0; traj < 20; ++traj) {
    RetargetData data;
    for (const RetargetFrame& f : trajectoryFrames(m, rng, 100, false)) {
      const RetargetResult& r = solveRetarget(m, params, data, f.p_target_TH, f.q_target);
      const JointVector q_goal = clampToLimits(m, f.q_target);
      const double dx = (r.q_x - q_goal).norm(), dq = (r.q_q - q_goal).norm();
      sum_x += dx;
      sum_q += dq;
      n_closer += dq <= dx + 1e-9;
      ++n_frames;
    }
  }
  const double ratio = sum_q / sum_x;
  MESSAGE("mean |q_x - q_target| = " << sum_x / n_frames << " rad, mean |q_q - q_target| = " << sum_q / n_frames
                                     << " rad (ratio " << ratio << "), q_q closer on " << n_closer << "/" << n_frames
                                     << " frames");
  CHECK_MESSAGE(ratio <= 0.01, "expected mean |q_q - q_target| <= 1 % of mean |q_x - q_target|, got " << 100.0 * ratio
                                                                                                         << " %");
  CHECK_MESSAGE(sum_q / n_frames < 1e-6, "expected mean |q_q - q_target| < 1e-6 rad, got " << sum_q / n_frames);
}

TEST_CASE("the fixed-size LM and the Ceres version agree within 1e-4 rad on every frame of 12 smooth trajectories") {
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(606);
  double worst_x = 0.0, worst_q = 0.0;
  int n_frames = 0;
  for (int traj = 0; traj < 12; ++traj) {
    const std::vector<RetargetFrame> frames = trajectoryFrames(m, rng, 100, traj % 3 == 2);
    const auto lm = nao::tools::retargetSequenceLM(m, params, frames);
    const auto cs = nao::tools::retargetSequenceCeres(m, params, frames);
    const nao::tools::RetargetAgreement a = nao::tools::compareRetarget(lm, cs);
    CHECK_MESSAGE(std::max(a.max_abs_q_x, a.max_abs_q_q) < 1e-4,
                  "trajectory " << traj << ": expected agreement < 1e-4 rad, got q_x " << a.max_abs_q_x << ", q_q "
                                << a.max_abs_q_q << " (worst frame " << a.worst_frame << ", flags "
                                << lm[a.worst_frame].flags << "/" << cs[a.worst_frame].flags << ", outer iterations "
                                << lm[a.worst_frame].iterations_outer << "/" << cs[a.worst_frame].iterations_outer << ")");
    worst_x = std::max(worst_x, a.max_abs_q_x);
    worst_q = std::max(worst_q, a.max_abs_q_q);
    n_frames += static_cast<int>(frames.size());
  }
  MESSAGE("LM vs Ceres over " << n_frames << " frames: max |dq_x| = " << worst_x << " rad, max |dq_q| = " << worst_q
                              << " rad");
}

TEST_CASE("the same frames twice give bitwise-equal results") {
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(707);
  const std::vector<RetargetFrame> frames = trajectoryFrames(m, rng, 200, false);
  const auto a = nao::tools::retargetSequenceLM(m, params, frames);
  const auto b = nao::tools::retargetSequenceLM(m, params, frames);
  REQUIRE(a.size() == b.size());
  int n_diff = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    n_diff += std::memcmp(a[i].q_x.data(), b[i].q_x.data(), sizeof(double) * kNumJoints) != 0;
    n_diff += std::memcmp(a[i].q_q.data(), b[i].q_q.data(), sizeof(double) * kNumJoints) != 0;
    n_diff += a[i].flags != b[i].flags || a[i].iterations_total != b[i].iterations_total;
  }
  CHECK_MESSAGE(n_diff == 0, "expected identical runs, got " << n_diff << " differing fields");
}

TEST_CASE("a non-finite target holds the previous pose and sets kRetargetBadInput without throwing") {
  const ArmModel& m = arm();
  const RetargetParams params;
  RetargetData data;
  JointVector q0;
  q0 << 1.0, -0.3, 0.5, 0.8, 0.1;
  ArmData d;
  const Eigen::Vector3d p0 = forwardKinematics(m, d, q0);
  const RetargetResult good = solveRetarget(m, params, data, p0, q0);
  CHECK(good.flags == 0);
  const Eigen::Vector3d nan_target(std::nan(""), 0.0, 0.0);
  const RetargetResult& bad = solveRetarget(m, params, data, nan_target, q0);
  CHECK_MESSAGE((bad.flags & kRetargetBadInput) != 0, "expected kRetargetBadInput, got flags " << bad.flags);
  CHECK_MESSAGE(bad.q_q == good.q_q, "expected the previous q_q held, got " << bad.q_q.transpose());
  CHECK_MESSAGE(bad.q_x == good.q_x, "expected the previous q_x held, got " << bad.q_x.transpose());
  JointVector q_nan = q0;
  q_nan[2] = std::numeric_limits<double>::infinity();
  CHECK((solveRetarget(m, params, data, p0, q_nan).flags & kRetargetBadInput) != 0);
  // A zero pointing direction is dropped, not used.
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const RetargetResult& r = solveRetarget(m, params, data, p0, q0, &zero);
  CHECK((r.flags & kRetargetBadPointing) != 0);
  CHECK(r.error_x_m < 1e-3);
}

TEST_CASE("an unreachable target is flagged and q_x gets as close as the arm allows") {
  const ArmModel& m = arm();
  const RetargetParams params;
  RetargetData data;
  // 1 m straight ahead of the shoulder: the arm points at it, fully stretched.
  const Eigen::Vector3d target(1.0, -0.098, 0.1);
  const RetargetResult& r = solveRetarget(m, params, data, target, JointVector::Zero());
  CHECK_MESSAGE((r.flags & kRetargetXUnreachable) != 0, "expected the unreachable flag, got flags " << r.flags);
  // Best possible: distance minus the reach from the shoulder (arm stretched along x).
  ArmData d;
  const double reach = (forwardKinematics(m, d, JointVector::Zero()) - d.p_TJ[0]).norm();
  const double best = (target - d.p_TJ[0]).norm() - reach;
  CHECK_MESSAGE(r.error_x_m < best + 1e-3, "expected error close to " << best << " m, got " << r.error_x_m << " m");
}

TEST_CASE("a non-finite target right after a reset to a measured pose holds that pose, inside the limits") {
  const ArmModel& m = arm();
  const RetargetParams params;
  RetargetData data;
  JointVector q_measured;
  q_measured << 0.3, -0.4, 0.5, 0.0, 0.2;  // ElbowRoll 0 is below its 2 deg limit: clamped
  resetRetarget(m, data, q_measured);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const RetargetResult& r = solveRetarget(m, params, data, Eigen::Vector3d(nan, 0.0, 0.0), JointVector::Zero());
  CHECK((r.flags & kRetargetBadInput) != 0);
  const JointVector expected = clampToLimits(m, q_measured);
  CHECK(r.q_x == expected);
  CHECK(r.q_q == expected);
  ArmData d;
  CHECK((r.p_TH_x - forwardKinematics(m, d, expected)).norm() < 1e-12);
}
