// nao_toolchain evaluate (docs/evaluate.md): the linear AR baseline's fit and rollout checked
// against what is known exactly, the DTW helpers, the command limiter and the rollout step.
#include "nao/kinematics.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/metrics.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

using namespace nao;
using namespace nao::tools;

namespace {

namespace fs = std::filesystem;

// Exactly autoregressive trajectories: a_j(t) = c_j + β_j q_j(t) + α_j1 a_j(t−1) + α_j2 a_j(t−2),
// q(t+1) = q(t) + a(t), from rest at q0 (a = 0 before t = 0, as the fit assumes).
struct TrueAr {
  JointVector c, beta, alpha1, alpha2;
};
TrueAr trueAr() {
  TrueAr m;
  for (int j = 0; j < kNumJoints; ++j) {
    m.beta[j] = -0.04 - 0.01 * j;
    m.c[j] = -m.beta[j] * (0.3 - 0.1 * j);  // fixed point q* = 0.3 − 0.1 j
    m.alpha1[j] = 0.5 + 0.08 * j;
    m.alpha2[j] = -0.2 + 0.03 * j;
  }
  return m;
}
std::vector<JointVector> arTrajectory(const TrueAr& m, const JointVector& q0, int n) {
  std::vector<JointVector> f{q0};
  JointVector a1 = JointVector::Zero(), a2 = JointVector::Zero();
  for (int t = 0; t + 1 < n; ++t) {
    const JointVector& q = f.back();
    JointVector a;
    for (int j = 0; j < kNumJoints; ++j) a[j] = m.c[j] + m.beta[j] * q[j] + m.alpha1[j] * a1[j] + m.alpha2[j] * a2[j];
    f.push_back(q + a);
    a2 = a1;
    a1 = a;
  }
  return f;
}

}  // namespace

TEST_CASE("the linear AR fit recovers the coefficients of an exactly autoregressive trajectory and picks its order") {
  const TrueAr truth = trueAr();
  std::vector<std::vector<JointVector>> train, val;
  for (int k = 0; k < 4; ++k)
    train.push_back(arTrajectory(truth, JointVector::Constant(-0.5 + 0.3 * k), 60 + 5 * k));
  for (int k = 0; k < 2; ++k) val.push_back(arTrajectory(truth, JointVector::Constant(0.9 - 0.7 * k), 50));
  const LinearArModel m = fitLinearAr(train, val, 6);
  for (int j = 0; j < kNumJoints; ++j) {
    const LinearArJoint& mj = m.joints[static_cast<std::size_t>(j)];
    CHECK_MESSAGE(mj.order == 2, "joint " << j << ": order " << mj.order << " chosen, the trajectory is AR(2)");
    REQUIRE(mj.alpha.size() == static_cast<std::size_t>(mj.order));
    CHECK(mj.c == doctest::Approx(truth.c[j]).epsilon(1e-8));
    CHECK(mj.beta == doctest::Approx(truth.beta[j]).epsilon(1e-8));
    CHECK(mj.alpha[0] == doctest::Approx(truth.alpha1[j]).epsilon(1e-8));
    CHECK(mj.alpha[1] == doctest::Approx(truth.alpha2[j]).epsilon(1e-8));
    CHECK(mj.train_mse < 1e-20);
    // Order 1 cannot represent it: its validation error is far above the chosen one's.
    CHECK(mj.val_mse_by_order[0] > 1e6 * (mj.val_mse_by_order[1] + 1e-30));
  }
  // The fitted model predicts the held-out trajectory's next action exactly.
  const std::vector<JointVector>& f = val[0];
  const std::vector<JointVector> past{f[9] - f[8], f[8] - f[7]};
  CHECK((linearArAction(m, f[9], past) - (f[10] - f[9])).norm() < 1e-10);
}

TEST_CASE("the linear AR fit refuses an order out of range or too few samples") {
  const std::vector<std::vector<JointVector>> one{{JointVector::Zero(), JointVector::Ones()}};
  CHECK_THROWS_AS(fitLinearArJoint(one, 0, 0), std::invalid_argument);
  CHECK_THROWS_AS(fitLinearArJoint(one, 0, kMaxLinearArOrder + 1), std::invalid_argument);
  CHECK_THROWS_AS(fitLinearArJoint(one, 0, 3), std::invalid_argument);  // 1 equation, 5 unknowns
}

TEST_CASE("a demonstration's DTW to itself is 0 and its nearest other demonstration is the closest shifted copy") {
  HandPath base;
  for (int t = 0; t < 40; ++t) base.push_back(Eigen::Vector3d(0.1 * std::cos(0.2 * t), 0.1 * std::sin(0.2 * t), 0.0));
  auto shifted = [&](double dz) {
    HandPath p = base;
    for (auto& v : p) v.z() += dz;
    return p;
  };
  const std::vector<HandPath> demos{base, shifted(0.03), shifted(0.01), shifted(-0.02)};
  CHECK(rt::dtwMeanDistance(base, base) == 0.0);
  const NearestDemo self = nearestDemo(base, demos);
  CHECK(self.index == 0);
  CHECK(self.dtw_m == 0.0);
  const NearestDemo other = nearestDemo(base, demos, 0);
  CHECK(other.index == 2);
  CHECK(other.dtw_m == doctest::Approx(0.01).epsilon(1e-9));
  CHECK(median({3.0, 1.0, 2.0}) == 2.0);
  CHECK(median({4.0, 1.0, 2.0, 3.0}) == 2.5);
  CHECK(std::isnan(median({})));
}

TEST_CASE("limitCommand cuts q + a to the position limits and one period of the velocity limit, as controller step 4") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const double period = 0.1;
  bool limited = true;
  const JointVector q = 0.5 * (arm.q_min + arm.q_max);
  const JointVector small = JointVector::Constant(1e-3);
  CHECK(limitCommand(arm, period, q, small, limited) == q + small);
  CHECK_FALSE(limited);
  const JointVector big = JointVector::Constant(10.0);
  const JointVector c = limitCommand(arm, period, q, big, limited);
  CHECK(limited);
  for (int j = 0; j < kNumJoints; ++j)
    CHECK(c[j] == doctest::Approx(std::min(arm.q_max[j], q[j] + arm.v_max[j] * period)));
  const JointVector c2 = limitCommand(arm, period, arm.q_min, -big, limited);
  CHECK(c2 == arm.q_min);
}

TEST_CASE("a workspace envelope keeps the command inside it within one period's reach, and pulls an arm outside back at full speed") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const double period = 0.1;
  const JointVector mid = 0.5 * (arm.q_min + arm.q_max);
  JointEnvelope env;
  env.lo = mid - JointVector::Constant(0.02);
  env.hi = mid + JointVector::Constant(0.02);
  JointVector c;
  // Inside: untouched.
  CHECK(limitCommand(arm, period, mid, JointVector::Constant(0.01), c, &env) == 0u);
  CHECK(c == mid + JointVector::Constant(0.01));
  // A step past the envelope is cut to its edge.
  CHECK(limitCommand(arm, period, mid, JointVector::Constant(0.05), c, &env) == kCommandEnveloped);
  CHECK(c == env.hi);
  // An arm 1 rad above the envelope: the envelope's edge where one period reaches it, else the end
  // of the reach nearest to it.
  const JointVector above = env.hi + JointVector::Constant(1.0);
  const std::uint32_t flags = limitCommand(arm, period, above, JointVector::Constant(0.5), c, &env);
  CHECK((flags & kCommandEnveloped) != 0u);
  for (int j = 0; j < kNumJoints; ++j) {
    CAPTURE(j);
    JointVector lo, hi;
    commandBounds(arm, period, above, lo, hi);
    CHECK(c[j] == (env.hi[j] >= lo[j] ? env.hi[j] : lo[j]));
    CHECK(c[j] < above[j]);
  }
  // Without an envelope the same command only meets the arm's own limits.
  CHECK((limitCommand(arm, period, mid, JointVector::Constant(0.05), c) & kCommandEnveloped) == 0u);
}

TEST_CASE("a rollout of the zero action holds the simulated arm at s_0, one hand point per tick plus the start") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const SimModel sim = makeSimModel(arm);
  const JointVector q0 = (JointVector() << 0.8, -0.3, 1.0, 0.6, 0.2).finished();
  SimData data(sim, q0);
  const Rollout r = rolloutOnSim(sim, data, 0.1, q0, 30,
                                 [](const JointVector&, const std::vector<JointVector>&) { return JointVector::Zero(); });
  REQUIRE(r.hand.size() == 31);
  REQUIRE(r.q.size() == 30);
  double worst = 0.0;
  for (const auto& p : r.hand) worst = std::max(worst, (p - r.hand.front()).norm());
  CHECK_MESSAGE(worst < 2e-3, "hand drifted " << worst * 1e3 << " mm holding s_0");
  CHECK(r.limited_ticks == 0);
  // The same rollout twice is the same bit for bit (the data is reset).
  const Rollout again = rolloutOnSim(sim, data, 0.1, q0, 30,
                                     [](const JointVector&, const std::vector<JointVector>&) { return JointVector::Zero(); });
  CHECK(again.q == r.q);
}

// The whole evaluation (nao_rt runs, medoid replay, speed, loops, network share, summary.json's
// contract for every movement) runs end to end on a model of a user's recordings in the system
// test open_world (tests/system/open_world.py); its measures are checked on closed-form paths in
// test_movement_metrics.

TEST_CASE("the neighbour replays are the 5 training demonstrations nearest the start, each tracked from it; the medoid's is the medoid replay") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const SimModel sim = makeSimModel(arm);
  const double period = 0.1, gain = servoStepGain(sim.params);
  // Seven demonstrations: slow circles of the shoulder and elbow around starts spread along the
  // joint ranges, each of its own radius and phase.
  DemoSet train;
  const JointVector mid = 0.5 * (arm.q_min + arm.q_max), span = arm.q_max - arm.q_min;
  for (int d = 0; d < 7; ++d) {
    std::vector<JointVector> f;
    const JointVector centre = mid + (0.04 * (d - 3)) * span;
    for (int t = 0; t < 60; ++t) {
      const double th = 0.2 * t + 0.3 * d, radius = 0.1 + 0.02 * d;
      JointVector q = centre;
      q[0] += radius * std::cos(th);
      q[1] += radius * std::sin(th);
      q[3] += 0.5 * radius * std::sin(th);
      f.push_back(q);
    }
    train.names.push_back("d" + std::to_string(d));
    train.start.push_back(f.front());
    train.hand.push_back(handPath(arm, f));
    train.f.push_back(std::move(f));
  }
  const JointVector start = train.start[2] + JointVector::Constant(0.01);
  const NeighbourReplays r = neighbourReplays(sim, period, gain, train, start, 60);
  CHECK(r.demos == nearestStarts(train.start, start, 5));
  CHECK(r.demos.front() == 2);
  CHECK(r.medoid == medoid(train.hand, r.demos));
  REQUIRE(r.q.size() == 5);
  double worst = 0.0;
  for (std::size_t k = 0; k < r.q.size(); ++k) {
    CAPTURE(k);
    const std::vector<JointVector>& f = train.f[static_cast<std::size_t>(r.demos[k])];
    // Each is its demonstration tracked from the run's start: the same as trackDemo of it, and
    // (the arm started 0.01 rad off, the servo a tick behind) near its hand path.
    CHECK(r.q[k] == trackDemo(sim, period, gain, f, start, 60));
    REQUIRE(r.q[k].size() == 61);
    const double dtw = rt::dtwMeanDistance(handPath(arm, r.q[k]), handPath(arm, f));
    worst = std::max(worst, dtw);
    CHECK_MESSAGE(dtw < 0.005, "replay of " << train.names[static_cast<std::size_t>(r.demos[k])] << " " << dtw * 1e3 << " mm off");
    // and farther from the other demonstrations than from its own.
    for (int other : r.demos)
      if (other != r.demos[k]) CHECK(dtw < rt::dtwMeanDistance(handPath(arm, r.q[k]), train.hand[static_cast<std::size_t>(other)]));
  }
  MESSAGE("neighbour replays: worst hand-path DTW to their own demonstration " << worst * 1e3 << " mm");
  CHECK(&r.medoidQ() == &r.q[static_cast<std::size_t>(std::find(r.demos.begin(), r.demos.end(), r.medoid) - r.demos.begin())]);
}

TEST_CASE("speed against the replay: a run that is its replay moves at 1, one at half its displacement per tick at 0.5") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const SimModel sim = makeSimModel(arm);
  const double period = 0.1, gain = servoStepGain(sim.params);
  // A demonstration circling the shoulder, its medoid replay from a start off it.
  std::vector<JointVector> f;
  const JointVector mid = 0.5 * (arm.q_min + arm.q_max);
  for (int t = 0; t < 80; ++t) {
    JointVector q = mid;
    q[0] += 0.15 * std::cos(0.25 * t);
    q[1] += 0.15 * std::sin(0.25 * t);
    f.push_back(q);
  }
  const HandPath replay = handPath(arm, trackDemo(sim, period, gain, f, f.front() + JointVector::Constant(0.02), 80));
  // The same path at half the displacement per tick (shrunk about its first point) and at twice.
  HandPath half, twice;
  for (const Eigen::Vector3d& p : replay) {
    half.push_back(replay.front() + 0.5 * (p - replay.front()));
    twice.push_back(replay.front() + 2.0 * (p - replay.front()));
  }
  const std::vector<double> ratio = speedVsReplay({replay, half, twice}, {replay, replay, replay}, period);
  REQUIRE(ratio.size() == 3);
  CHECK(ratio[0] == 1.0);
  CHECK(ratio[1] == doctest::Approx(0.5).epsilon(1e-12));
  CHECK(ratio[2] == doctest::Approx(2.0).epsilon(1e-12));
  // Against another replay it is that replay's speed that divides: the half-speed path is the bar.
  CHECK(speedVsReplay({replay}, {half}, period).front() == doctest::Approx(2.0).epsilon(1e-12));
  // A replay that holds still has no speed to compare with; the counts must match.
  CHECK(std::isnan(speedVsReplay({replay}, {HandPath(80, replay.front())}, period).front()));
  CHECK_THROWS_AS(speedVsReplay({replay, half}, {replay}, period), std::invalid_argument);
}
