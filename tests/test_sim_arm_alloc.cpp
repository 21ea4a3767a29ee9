// Real-time property: after configure, the kinematics and the simulated arm allocate nothing.
#include "nao/sim_arm.hpp"
#include "support/alloc_counter.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <random>
#include <vector>

using namespace nao;
using nao::test::CountAllocations;

namespace {
// Keeps the optimiser from removing an allocation whose result is otherwise unused.
void escape(void* p) { asm volatile("" : : "g"(p) : "memory"); }
}  // namespace

TEST_CASE("the counting allocator sees malloc, calloc, realloc and operator new") {
  CountAllocations c;
  void* p = std::malloc(16);
  escape(p);
  p = std::realloc(p, 64);
  escape(p);
  void* z = std::calloc(4, 4);
  escape(z);
  std::free(p);
  std::free(z);
  auto* i = new int(3);
  escape(i);
  delete i;
  std::vector<double> v(100);
  escape(v.data());
  const std::int64_t n_alloc = c.count();
  CHECK(n_alloc == 5);
}

TEST_CASE("1000 simulated ticks after configure allocate nothing") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const SimModel model = makeSimModel(arm);
  JointVector q0;
  q0 << 1.4, -0.2, 1.2, 0.5, 0.0;
  SimData sim(model, q0);
  // Commands prepared before counting; the loop must not allocate for them either.
  std::mt19937_64 rng(1);
  std::vector<JointVector> commands;
  for (int i = 0; i < 100; ++i) commands.push_back(nao::test::randomPose(arm, rng));

  CountAllocations counter;
  for (int tick = 0; tick < 1000; ++tick) stepSim(model, sim, commands[tick / 10]);
  resetSim(model, sim, q0);
  for (int tick = 0; tick < 10; ++tick) stepSim(model, sim, commands[tick]);
  // Read before asserting: doctest's message machinery allocates.
  const std::int64_t n_alloc = counter.count();
  CHECK_MESSAGE(n_alloc == 0, n_alloc << " heap allocations in 1010 ticks and a reset");
}

TEST_CASE("forward kinematics and the Jacobian allocate nothing") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  ArmData d;
  std::mt19937_64 rng(2);
  std::vector<JointVector> poses;
  for (int i = 0; i < 1000; ++i) poses.push_back(nao::test::randomPose(arm, rng));
  CountAllocations counter;
  double sink = 0.0;
  for (const JointVector& q : poses) {
    sink += forwardKinematics(arm, d, q).x();
    sink += handJacobian(arm, d)(0, 0);
  }
  const std::int64_t n_alloc = counter.count();
  CHECK(n_alloc == 0);
  CHECK(std::isfinite(sink));
}
