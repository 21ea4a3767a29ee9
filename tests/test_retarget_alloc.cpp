// Real-time property: the online retargeting (fixed-size LM, Algorithm 1) allocates nothing.
#include "nao/retarget.hpp"
#include "support/alloc_counter.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <vector>

using namespace nao;
using nao::test::CountAllocations;

TEST_CASE("10,000 retarget solves (q_x and q_q, with and without pointing, bad input) allocate nothing") {
  const ArmModel m = loadArmModel(nao::test::kUrdfPath);
  const RetargetParams params;
  RetargetData data;
  ArmData d;
  // Targets prepared before counting: FK of random poses, joint targets offset (some outside
  // the limits), every 7th frame an unreachable target, every 101st a NaN.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> offset(-0.5, 0.5);
  constexpr int kSolves = 10000;
  std::vector<Eigen::Vector3d> p_targets, u_targets;
  std::vector<JointVector> q_targets;
  for (int i = 0; i < kSolves; ++i) {
    const JointVector q = nao::test::randomPose(m, rng);
    Eigen::Vector3d p = forwardKinematics(m, d, q);
    if (i % 7 == 0) p.x() += 1.0;
    if (i % 101 == 0) p.y() = std::nan("");
    p_targets.push_back(p);
    u_targets.push_back(d.u_TH);
    JointVector qt = q;
    for (int j = 0; j < kNumJoints; ++j) qt[j] += offset(rng);
    q_targets.push_back(qt);
  }

  double sink = 0.0;
  int n_bad = 0;
  CountAllocations counter;
  for (int i = 0; i < kSolves; ++i) {
    const RetargetResult& r = solveRetarget(m, params, data, p_targets[i], q_targets[i], i % 3 == 0 ? &u_targets[i] : nullptr);
    sink += r.q_x[0] + r.q_q[0];
    n_bad += (r.flags & kRetargetBadInput) != 0;
  }
  const std::int64_t n_alloc = counter.count();
  CHECK_MESSAGE(n_alloc == 0, "expected no heap allocation in " << kSolves << " solves, got " << n_alloc);
  CHECK(std::isfinite(sink));
  CHECK(n_bad == (kSolves + 100) / 101);
}
