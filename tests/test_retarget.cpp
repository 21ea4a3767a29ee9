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

// The solver's own precision is tested with the posture nearly free (mu 1e-6 m^2/rad^2: 1 rad for
// 1 mm). The default price (3e-5) trades a fraction of a millimetre of reach for a calm posture
// at the rim of the workspace (retarget.hpp); those tests say so where they use it.
RetargetParams reachParams() {
  RetargetParams p;
  p.mu = 1e-6;
  return p;
}

bool insideLimits(const ArmModel& m, const JointVector& q) {
  return (q.array() >= m.q_min.array()).all() && (q.array() <= m.q_max.array()).all();
}

}  // namespace

TEST_CASE("q_x reaches every target of 20 warm-started smooth trajectories within 1 mm (posture nearly free); the default price costs a median < 1 mm") {
  const ArmModel& m = arm();
  const RetargetParams params = reachParams(), defaults;
  std::mt19937_64 rng(101);
  double worst = 0.0;
  int n_frames = 0, n_flagged_x = 0;
  std::vector<double> miss_default;
  for (int traj = 0; traj < 20; ++traj) {
    RetargetData data, data_default;
    for (const RetargetFrame& f : trajectoryFrames(m, rng, 100, false)) {
      const RetargetResult& r = solveRetarget(m, params, data, f.p_target_TH, f.q_target);
      worst = std::max(worst, r.error_x_m);
      n_flagged_x += (r.flags & (kRetargetXCapHit | kRetargetXUnreachable)) != 0;
      miss_default.push_back(solveRetarget(m, defaults, data_default, f.p_target_TH, f.q_target).error_x_m);
      ++n_frames;
    }
  }
  std::sort(miss_default.begin(), miss_default.end());
  const double median_default = miss_default[miss_default.size() / 2];
  MESSAGE("largest q_x hand error over " << n_frames << " frames: " << worst * 1e3 << " mm (mu " << params.mu
                                         << "); with the default mu " << defaults.mu << ": median "
                                         << median_default * 1e3 << " mm, largest " << miss_default.back() * 1e3 << " mm");
  CHECK_MESSAGE(worst < 1e-3, "expected every hand error < 1 mm, got a largest error of " << worst * 1e3 << " mm");
  CHECK_MESSAGE(n_flagged_x == 0, "expected no q_x cap/unreachable flags, got " << n_flagged_x);
  // These trajectories pull the posture hard (joint targets up to ~1 rad off the hand's pose).
  CHECK_MESSAGE(median_default < 1e-3, "expected the default posture price to cost a median < 1 mm of reach, got "
                                           << median_default * 1e3 << " mm");
}

TEST_CASE("q_x reaches a reachable target from an unrelated random start in at least 85 % of 2000 cases") {
  // Far starts (a random pose to another random pose) can end in a local minimum against a
  // joint limit: measured 88.5 % success with this seed; the bound guards against regressions.
  // The warm-started case above is the one the runtime depends on and is asserted fully.
  // The anchor is the random start, radians from the answer: posture nearly free here.
  const ArmModel& m = arm();
  const RetargetParams params = reachParams();
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

TEST_CASE("joint priority lands on its fixed point lambda_q (x(q_q) - x_target) = J (q_goal - q_q) on 20 trajectories") {
  // The outer loop's fixed point (retarget.hpp): the hand pulled from x_target toward where the
  // clamped human angles put it, priced by lambda_q. Checked on the solution itself, independent
  // of how the loop got there. The equation is the mu -> 0 limit: with the posture nearly free
  // (mu 1e-6) the IK's own miss (~1e-5 m) bounds the residual.
  const ArmModel& m = arm();
  const RetargetParams params = reachParams();
  std::mt19937_64 rng(505);
  ArmData d;
  double worst_residual = 0.0, sum_ratio = 0.0, sum_dq = 0.0;
  int n_frames = 0, n_conflict = 0, n_moved = 0, n_closer_hand = 0;
  for (int traj = 0; traj < 20; ++traj) {
    RetargetData data;
    for (const RetargetFrame& f : trajectoryFrames(m, rng, 100, false)) {
      const RetargetResult& r = solveRetarget(m, params, data, f.p_target_TH, f.q_target);
      ++n_frames;
      if (r.flags & (kRetargetQCapHit | kRetargetInnerCapHit | kRetargetFallback)) continue;
      const JointVector q_goal = clampToLimits(m, f.q_target);
      forwardKinematics(m, d, r.q_q);
      handJacobian(m, d);
      const Eigen::Vector3d residual = params.lambda_q * (d.p_TH - f.p_target_TH) - d.Jp_TH * (q_goal - r.q_q);
      worst_residual = std::max(worst_residual, residual.norm());
      // Where the targets conflict (the clamped angles miss the hand target by > 5 mm), q_q is
      // neither the clamp nor q_x: its hand is between, about 1/(1 + lambda_q) of the way.
      if (r.error_clamp_m > 5e-3) {
        ++n_conflict;
        const double miss_q = (r.p_TH_q - f.p_target_TH).norm();
        sum_ratio += miss_q / r.error_clamp_m;
        n_closer_hand += miss_q < r.error_clamp_m;
        const double dq = (r.q_q - q_goal).norm();
        sum_dq += dq;
        n_moved += dq > 1e-3;
      }
    }
  }
  const double mean_ratio = sum_ratio / n_conflict;
  MESSAGE(n_frames << " frames, " << n_conflict << " with conflicting targets: worst fixed-point residual "
                   << worst_residual << " m; mean hand miss of q_q / miss of the clamp " << mean_ratio
                   << " (first order: " << 1.0 / (1.0 + params.lambda_q) << "); mean |q_q - clamp| "
                   << sum_dq / n_conflict << " rad");
  REQUIRE(n_conflict > 500);
  CHECK_MESSAGE(worst_residual < 1e-4, "expected the fixed-point equation to hold within 1e-4 m, got " << worst_residual);
  CHECK_MESSAGE(n_moved == n_conflict, "expected q_q to differ from the clamped angles (> 1e-3 rad) on every conflicting "
                                       "frame, it did on " << n_moved << "/" << n_conflict);
  CHECK_MESSAGE(n_closer_hand == n_conflict, "expected q_q's hand nearer x_target than the clamp's on every conflicting "
                                             "frame, it was on " << n_closer_hand << "/" << n_conflict);
  CHECK_MESSAGE(std::abs(mean_ratio - 1.0 / (1.0 + params.lambda_q)) < 0.05,
                "expected the mean miss ratio near 1/(1+lambda_q) = " << 1.0 / (1.0 + params.lambda_q) << ", got "
                                                                      << mean_ratio);
}

TEST_CASE("joint priority on a known case: a hand target d off the joint target's hand pulls q_q's hand by d lambda/(1+lambda)") {
  // q_goal inside the limits, x_target = x(q_goal) + d: to first order in |d| the fixed point
  // puts the hand at x(q_goal) + d lambda_q / (1 + lambda_q). 1 cm offsets, 3 directions, 3 lambdas.
  const ArmModel& m = arm();
  JointVector q_goal;
  q_goal << 0.4, -0.5, 1.0, 0.9, 0.3;
  ArmData d;
  const Eigen::Vector3d p_goal = forwardKinematics(m, d, q_goal);
  for (double lambda : {0.25, 1.0, 4.0}) {
    RetargetParams params = reachParams();  // the first-order answer is the mu -> 0 limit
    params.lambda_q = lambda;
    for (const Eigen::Vector3d& dir : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0.6, 0.8)}) {
      const Eigen::Vector3d offset = 0.01 * dir;
      RetargetData data;
      const RetargetResult& r = solveRetarget(m, params, data, p_goal + offset, q_goal);
      const Eigen::Vector3d expected = p_goal + offset * (lambda / (1.0 + lambda));
      const double miss = (r.p_TH_q - expected).norm();
      CAPTURE(lambda);
      CAPTURE(dir.transpose());
      // Second-order terms of a 1 cm offset on a 0.2 m arm: well under a millimetre.
      CHECK_MESSAGE(miss < 5e-4, "expected q_q's hand at " << expected.transpose() << ", got " << r.p_TH_q.transpose()
                                                           << " (" << miss * 1e3 << " mm off)");
      CHECK_MESSAGE((r.q_q - q_goal).norm() > 1e-3, "expected q_q to leave the joint target, |dq| = " << (r.q_q - q_goal).norm());
      CHECK_MESSAGE(r.error_x_m < 1e-4, "expected q_x on the hand target, missed by " << r.error_x_m);
    }
  }
}

TEST_CASE("lambda_q spans the trade-off: 0 gives the clamped human angles, a large value the hand-priority pose") {
  const ArmModel& m = arm();
  std::mt19937_64 rng(515);
  const std::vector<RetargetFrame> frames = trajectoryFrames(m, rng, 100, false);
  RetargetParams joints_only, hand_like;
  joints_only.lambda_q = 0.0;
  hand_like.lambda_q = 1e6;
  RetargetData a, b;
  double worst_clamp = 0.0, worst_hand = 0.0;
  for (const RetargetFrame& f : frames) {
    const RetargetResult& ra = solveRetarget(m, joints_only, a, f.p_target_TH, f.q_target);
    worst_clamp = std::max(worst_clamp, (ra.q_q - clampToLimits(m, f.q_target)).cwiseAbs().maxCoeff());
    const RetargetResult& rb = solveRetarget(m, hand_like, b, f.p_target_TH, f.q_target);
    worst_hand = std::max(worst_hand, (rb.p_TH_q - f.p_target_TH).norm());
  }
  MESSAGE("lambda_q = 0: max |q_q - clamp| = " << worst_clamp << " rad; lambda_q = 1e6: max hand miss of q_q = "
                                               << worst_hand * 1e3 << " mm");
  CHECK_MESSAGE(worst_clamp < 1e-5, "lambda_q = 0 should give the clamped angles, off by " << worst_clamp);
  CHECK_MESSAGE(worst_hand < 1e-3, "lambda_q = 1e6 should put the hand on x_target, missed by " << worst_hand);
}

TEST_CASE("q_r is q_x with hand priority and q_q with joint priority, and never misses the hand more than the clamp") {
  const ArmModel& m = arm();
  std::mt19937_64 rng(525);
  const std::vector<RetargetFrame> frames = trajectoryFrames(m, rng, 200, false);
  RetargetParams hand, joints;
  joints.priority = RetargetPriority::kJoints;
  RetargetData dh, dj;
  int n_worse = 0;
  for (const RetargetFrame& f : frames) {
    const RetargetResult& rh = solveRetarget(m, hand, dh, f.p_target_TH, f.q_target);
    CHECK(rh.q_r == rh.q_x);
    n_worse += (rh.error_x_m > rh.error_clamp_m + 1e-9);
    const RetargetResult& rj = solveRetarget(m, joints, dj, f.p_target_TH, f.q_target);
    CHECK(rj.q_r == rj.q_q);
    n_worse += ((rj.p_TH_q - f.p_target_TH).norm() > rj.error_clamp_m + 1e-9);
  }
  CHECK_MESSAGE(n_worse == 0, n_worse << " poses missed the hand target by more than the clamped angles");
}

TEST_CASE("a failed solve falls back to the clamped human angles and says so") {
  // One LM iteration from a far warm start cannot reach the target: q_x would be worse than
  // clamping, so q_r is the clamped joint target and kRetargetFallback is set.
  const ArmModel& m = arm();
  RetargetParams params;
  params.max_inner_iterations = 1;
  params.lambda_x = 1e3;  // heavy damping: the one step is tiny
  JointVector q_target;
  q_target << 0.2, -0.3, 0.8, 1.0, 0.0;
  ArmData d;
  const Eigen::Vector3d target = forwardKinematics(m, d, q_target) + Eigen::Vector3d(0.0, 0.0, 0.004);
  RetargetData data;
  JointVector far;
  far << 1.8, 0.2, -1.5, 0.1, 1.5;
  resetRetarget(m, data, far);
  const RetargetResult& r = solveRetarget(m, params, data, target, q_target);
  CHECK_MESSAGE((r.flags & kRetargetFallback) != 0, "expected the fallback flag, got flags " << r.flags);
  CHECK((r.flags & kRetargetXCapHit) != 0);
  CHECK(r.q_r == clampToLimits(m, q_target));
  CHECK(r.error_x_m <= r.error_clamp_m + 1e-12);
}

TEST_CASE("the fixed-size LM and Ceres agree within 1e-4 rad: q_x (the default q_r) on every frame, q_q on >= 99 % of 12 smooth trajectories") {
  // q_x is one bounded IK with a unique minimiser. q_q is the outer loop's fixed point: where the
  // clamped angles miss the hand target by centimetres with a joint pinned at its limit, the loop
  // can stop on its iteration cap, and the two solvers' 1e-8 differences then pick different
  // points of a flat valley. Such frames are counted, not hidden.
  const ArmModel& m = arm();
  const RetargetParams params;
  std::mt19937_64 rng(606);
  double worst_x = 0.0, worst_q = 0.0;
  int n_frames = 0, n_q_agree = 0, n_q_capped = 0;
  for (int traj = 0; traj < 12; ++traj) {
    const std::vector<RetargetFrame> frames = trajectoryFrames(m, rng, 100, traj % 3 == 2);
    const auto lm = nao::tools::retargetSequenceLM(m, params, frames);
    const auto cs = nao::tools::retargetSequenceCeres(m, params, frames);
    const nao::tools::RetargetAgreement a = nao::tools::compareRetarget(lm, cs);
    CHECK_MESSAGE(a.max_abs_q_x < 1e-4, "trajectory " << traj << ": expected q_x agreement < 1e-4 rad, got "
                                                      << a.max_abs_q_x << " (worst frame " << a.worst_frame << ")");
    for (std::size_t i = 0; i < frames.size(); ++i) {
      n_q_agree += (lm[i].q_q - cs[i].q_q).cwiseAbs().maxCoeff() < 1e-4;
      n_q_capped += ((lm[i].flags | cs[i].flags) & kRetargetQCapHit) != 0;
    }
    worst_x = std::max(worst_x, a.max_abs_q_x);
    worst_q = std::max(worst_q, a.max_abs_q_q);
    n_frames += static_cast<int>(frames.size());
  }
  const double share_q = static_cast<double>(n_q_agree) / n_frames;
  MESSAGE("LM vs Ceres over " << n_frames << " frames: max |dq_x| = " << worst_x << " rad; q_q within 1e-4 rad on "
                              << n_q_agree << " frames (" << 100.0 * share_q << " %), max |dq_q| = " << worst_q
                              << " rad; outer-loop cap hit by either solver on " << n_q_capped << " frames");
  CHECK_MESSAGE(share_q >= 0.99, "expected q_q to agree within 1e-4 rad on >= 99 % of frames, got " << 100.0 * share_q << " %");
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
  CHECK(r.q_r == expected);
  ArmData d;
  CHECK((r.p_TH_x - forwardKinematics(m, d, expected)).norm() < 1e-12);
}
