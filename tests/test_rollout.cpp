// The command limiter, a tick's command (nao/rollout.hpp) and the rollout step on a robot
// (nao/robot_backend.hpp): the one place where an action becomes a command and a period of
// the arm. Checked against what each limit means on its own,
// and the step against stepSim of the same command.
#include "nao/rollout.hpp"

#include "nao/arm_model.hpp"
#include "nao/robot_backend.hpp"
#include "nao/sim_arm.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <initializer_list>

#include <cmath>
#include <limits>
#include <random>

using namespace nao;

TEST_CASE("limitCommand passes q + a inside the limits, cuts it to one period's reach and to the position limits, and holds on a non-finite action") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const double T = 0.1;
  const JointVector q = (JointVector() << 0.5, -0.4, 0.3, 0.8, 0.2).finished();
  JointVector q_cmd;

  const JointVector small = JointVector::Constant(0.01);
  CHECK(limitCommand(arm, T, q, small, q_cmd) == 0u);
  CHECK(q_cmd == q + small);

  // One period's reach: |q_cmd - q| <= v_max T, exactly at the bound.
  const JointVector big = JointVector::Constant(5.0);
  CHECK(limitCommand(arm, T, q, big, q_cmd) == kCommandClamped);
  for (int j = 0; j < kNumJoints; ++j) CHECK(q_cmd[j] == std::min(arm.q_max[j], q[j] + arm.v_max[j] * T));
  CHECK(limitCommand(arm, T, q, -big, q_cmd) == kCommandClamped);
  for (int j = 0; j < kNumJoints; ++j) CHECK(q_cmd[j] == std::max(arm.q_min[j], q[j] - arm.v_max[j] * T));

  // At a position limit the command stays on it.
  CHECK(limitCommand(arm, T, arm.q_max, big, q_cmd) == kCommandClamped);
  CHECK(q_cmd == arm.q_max);

  // A joint far outside its limits (a measurement past the hinge stop) is pulled back by at most
  // one period's reach toward the range: the interval's ends swap.
  JointVector outside = q;
  outside[1] = arm.q_max[1] + 1.0;
  CHECK(limitCommand(arm, T, outside, JointVector::Zero(), q_cmd) == kCommandClamped);
  CHECK(q_cmd[1] == outside[1] - arm.v_max[1] * T);
  JointVector lo, hi;
  commandBounds(arm, T, outside, lo, hi);
  REQUIRE(arm.v_max[1] * T < 1.0);
  CHECK(lo[1] == arm.q_max[1]);
  CHECK(hi[1] == outside[1] - arm.v_max[1] * T);

  // NaN or Inf anywhere: hold (a = 0), flagged; the rest of the rule still applies.
  for (double bad : {std::nan(""), std::numeric_limits<double>::infinity()}) {
    JointVector a = small;
    a[3] = bad;
    CHECK(limitCommand(arm, T, q, a, q_cmd) == kCommandNonFinite);
    CHECK(q_cmd == q);
    CHECK(limitCommand(arm, T, outside, a, q_cmd) == (kCommandNonFinite | kCommandClamped));
    CHECK(q_cmd.allFinite());
  }
  bool limited = true;
  CHECK(limitCommand(arm, T, q, small, limited) == q + small);
  CHECK_FALSE(limited);
  limitCommand(arm, T, q, big, limited);
  CHECK(limited);
}

TEST_CASE("rolloutStep sends the limited command for one period: the same arm state as stepSim of that command, the applied action recorded") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const SimParams params;
  const double T = params.dt_s * params.substeps_per_tick;
  const JointVector q0 = (JointVector() << 1.2, -0.3, 1.0, 0.6, 0.1).finished();
  // The step through the backend, and the same commands straight into a second simulation.
  OdeArmBackend robot(arm, params, q0);
  const SimModel& model = robot.model();
  SimData twin(model, q0);
  robot.activate(q0);
  resetSim(model, twin, q0);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 0.3);
  CommandStep step;
  for (int t = 0; t < 30; ++t) {
    JointVector a;
    for (int j = 0; j < kNumJoints; ++j) a[j] = n(rng);
    if (t == 7) a[0] = std::nan("");
    JointVector expected_cmd;
    const std::uint32_t flags = limitCommand(arm, T, twin.q, a, expected_cmd);
    const JointVector q_before = twin.q;
    const JointVector& q = rolloutStep(arm, T, robot, a, step);
    stepSim(model, twin, expected_cmd);
    CHECK(step.q == q_before);
    CHECK(step.q_cmd == expected_cmd);
    CHECK(step.limit == flags);
    CHECK(step.a_applied == expected_cmd - q_before);
    CHECK(q == twin.q);  // bit for bit
    CHECK(&q == &robot.measured());
    if (t == 7) CHECK((step.limit & kCommandNonFinite) != 0);
  }
}

TEST_CASE("commandFor is the limited command and the action as taken and as applied, with no robot") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const double T = 0.1;
  const JointVector q = (JointVector() << 1.2, -0.3, 1.0, 0.6, 0.1).finished();
  JointEnvelope env;
  env.lo = q.array() - 0.02;
  env.hi = q.array() + 0.02;
  for (const JointEnvelope* e : std::initializer_list<const JointEnvelope*>{nullptr, &env}) {
    for (const JointVector& a : {JointVector(JointVector::Constant(0.01)), JointVector(JointVector::Constant(5.0)),
                                 JointVector((JointVector() << std::nan(""), 0.0, 0.0, 0.0, 0.0).finished())}) {
      JointVector expected;
      const std::uint32_t flags = limitCommand(arm, T, q, a, expected, e);
      const CommandStep step = commandFor(arm, T, q, a, e);
      CHECK(step.q == q);
      CHECK(step.q_cmd == expected);
      CHECK(step.limit == flags);
      CHECK(step.a_applied == expected - q);
      // The action as taken: a non-finite one is held (0), as the tick records it.
      CHECK(step.a == (a.allFinite() ? a : JointVector(JointVector::Zero())));
    }
  }
}
