// Simulated arm: behaves like NAO's position-servoed arm and is bitwise repeatable.
#include "nao/sim_arm.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <cstring>
#include <string>
#include <random>
#include <vector>

using namespace nao;
using nao::test::kDeg;
using nao::test::kUrdfPath;

namespace {

JointVector pose(double a, double b, double c, double d, double e) {
  JointVector q;
  q << a, b, c, d, e;
  return q;
}

// Poses where gravity loads the shoulder most (arm horizontal) and NAO's usual rest pose.
const JointVector kForward = pose(0.0, -0.3, 0.0, 0.05, 0.0);
const JointVector kSide = pose(0.0, -1.3, 0.0, 0.05, 0.0);
const JointVector kRest = pose(1.4, -0.2, 1.2, 0.5, 0.0);
const JointVector kBent = pose(-0.5, -0.6, 1.0, 1.4, 1.0);

}  // namespace

TEST_CASE("the ODE bodies put the hand where forward kinematics of the measured angles does") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  const SimModel model = makeSimModel(arm);
  SimData sim(model, kRest);
  ArmData kin;
  std::mt19937_64 rng(3);
  for (int i = 0; i < 20; ++i) {
    stepSim(model, sim, nao::test::randomPose(arm, rng));
    const Eigen::Vector3d p_fk = forwardKinematics(arm, kin, sim.q);
    const Eigen::Vector3d p_ode = simHandPosition(model, sim);
    // Hinge constraints are solved to ODE's tolerance, not exactly.
    CHECK_MESSAGE((p_fk - p_ode).norm() < 1e-4, "tick " << i << ": FK " << p_fk.transpose() << ", ODE " << p_ode.transpose());
  }
}

TEST_CASE("holding a pose against gravity for 10 s keeps every joint within 0.5 degrees") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  const SimModel model = makeSimModel(arm);
  for (const JointVector& target : {kForward, kSide, kRest, kBent}) {
    SimData sim(model, target);
    double worst = 0.0;
    for (int tick = 0; tick < 100; ++tick) {
      stepSim(model, sim, target);
      worst = std::max(worst, (sim.q - target).cwiseAbs().maxCoeff());
    }
    CHECK_MESSAGE(worst < 0.5 * kDeg, "pose " << target.transpose() << ": worst deviation " << worst / kDeg << " deg");
  }
}

TEST_CASE("a 30 degree step on each joint settles within 1 degree in 1 s without passing its limit") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  // One physics step per tick, so every 1 ms sample is inspected for overshoot.
  SimParams fine;
  fine.substeps_per_tick = 1;
  const SimModel model = makeSimModel(arm, fine);
  const JointVector mid = pose(0.0, -0.5, 0.0, 0.8, 0.0);
  for (int j = 0; j < kNumJoints; ++j) {
    // Three steps per joint: +30 deg from mid-range, and 30 deg steps that end exactly on
    // the upper and on the lower limit (where any overshoot would leave the range).
    struct Step {
      double from, to;
    };
    const Step steps[] = {{mid[j], mid[j] + 30 * kDeg},
                          {arm.q_max[j] - 30 * kDeg, arm.q_max[j]},
                          {arm.q_min[j] + 30 * kDeg, arm.q_min[j]}};
    for (const Step& s : steps) {
      JointVector start = mid, target = mid;
      start[j] = s.from;
      target[j] = s.to;
      SimData sim(model, start);
      double worst_after_1s = 0.0, lowest = 1e9, highest = -1e9;
      for (int ms = 1; ms <= 2000; ++ms) {
        stepSim(model, sim, target);
        lowest = std::min(lowest, sim.q[j]);
        highest = std::max(highest, sim.q[j]);
        if (ms >= 1000) worst_after_1s = std::max(worst_after_1s, (sim.q - target).cwiseAbs().maxCoeff());
      }
      const std::string joint = kJointNames[j];
      CAPTURE(joint);
      CAPTURE(s.from);
      CAPTURE(s.to);
      CHECK_MESSAGE(worst_after_1s < 1.0 * kDeg, "error after 1 s: " << worst_after_1s / kDeg << " deg");
      // 1e-9 rad: ODE's hinge angle (from body quaternions) is exact only to rounding; an
      // overshoot would show as the servo's motion, orders of magnitude larger.
      CHECK_MESSAGE(highest <= arm.q_max[j] + 1e-9, "passed the upper limit by " << highest - arm.q_max[j] << " rad");
      CHECK_MESSAGE(lowest >= arm.q_min[j] - 1e-9, "passed the lower limit by " << arm.q_min[j] - lowest << " rad");
    }
  }
}

TEST_CASE("joint speeds stay within 5% of the URDF velocity limits, even for full-range steps") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  const SimModel model = makeSimModel(arm);
  SimData sim(model, arm.q_min);
  JointVector peak = JointVector::Zero();
  // Full-range swings in both directions, all joints at once, then random jumps.
  for (int k = 0; k < 6; ++k) {
    const JointVector& target = (k % 2 == 0) ? arm.q_max : arm.q_min;
    for (int tick = 0; tick < 15; ++tick) {
      stepSim(model, sim, target);
      peak = peak.cwiseMax(sim.qd_peak);
    }
  }
  std::mt19937_64 rng(5);
  for (int tick = 0; tick < 200; ++tick) {
    stepSim(model, sim, nao::test::randomPose(arm, rng));
    peak = peak.cwiseMax(sim.qd_peak);
  }
  for (int j = 0; j < kNumJoints; ++j) {
    const std::string joint = kJointNames[j];
    CAPTURE(joint);
    CHECK_MESSAGE(peak[j] <= 1.05 * arm.v_max[j], "peak " << peak[j] << " rad/s, limit " << arm.v_max[j]);
    // The swings are long enough to reach the velocity limit: the cap is what bounds them.
    CHECK_MESSAGE(peak[j] >= 0.9 * arm.v_max[j], "peak " << peak[j] << " rad/s never approached " << arm.v_max[j]);
  }
}

TEST_CASE("two runs of the same command sequence give bitwise-equal joint trajectories") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  const SimModel model = makeSimModel(arm);
  auto run = [&] {
    SimData sim(model, kRest);
    std::mt19937_64 rng(42);
    std::vector<double> out;
    for (int tick = 0; tick < 300; ++tick) {
      const JointVector cmd = tick % 10 == 0 ? nao::test::randomPose(arm, rng) : sim.q_cmd;
      stepSim(model, sim, cmd);
      out.insert(out.end(), sim.q.data(), sim.q.data() + kNumJoints);
      out.insert(out.end(), sim.qd.data(), sim.qd.data() + kNumJoints);
    }
    return out;
  };
  const std::vector<double> a = run();
  const std::vector<double> b = run();
  REQUIRE(a.size() == b.size());
  CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
  // And the trajectory did go somewhere: this is not comparing two idle arms.
  double travel = 0.0;
  for (std::size_t i = kNumJoints * 2; i < a.size(); i += 2 * kNumJoints) travel += std::abs(a[i] - a[i - 2 * kNumJoints]);
  CHECK(travel > 1.0);
}

TEST_CASE("simulation parameters out of range are refused at configure time") {
  const ArmModel arm = loadArmModel(kUrdfPath);
  SimParams p;
  p.dt_s = 0.0;
  CHECK_THROWS_AS(makeSimModel(arm, p), std::invalid_argument);
  p = SimParams{};
  p.servo_gain_per_s = 2000.0;  // K dt >= 1 would make the discrete servo unstable
  CHECK_THROWS_AS(makeSimModel(arm, p), std::invalid_argument);
  ArmModel weak = arm;
  weak.tau_max[0] = 0.1;  // cannot hold the arm against gravity
  CHECK_THROWS_WITH_AS(makeSimModel(weak, SimParams{}), doctest::Contains("RShoulderPitch"), ArmModelError);
}
