// Real-time property of the whole tick: from activate through 6,000 ticks (10 simulated
// minutes: retargeting, policy, ODE, faults included) nothing is allocated.
#include "nao/controller.hpp"
#include "nao/robot_loop.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/reference_source.hpp"
#include "support/alloc_counter.hpp"
#include "support/policy_faults.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

using namespace nao;

namespace {

template <class Dims>
void checkNoAllocation(std::uint64_t seed, const PolicyArch& arch = Dims::arch()) {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const test::RandomPolicy random = test::makeRandomPolicy(arch, arm, seed);
  const PolicyWeights<Dims> weights =
      bindPolicyWeights<Dims>(random.pointers.data(), random.pointers.size(), arch, Conditioning::kReference);
  std::vector<JointVector> centroids;
  for (int k = 0; k < weights.clusters; ++k) centroids.push_back(centroid(weights, 1, k).template cast<double>());
  const tools::ReferenceStream ref = tools::makeSyntheticReference(arm, tools::Movement::kWholeArm, 2, 0, centroids);
  const ControllerModel<Dims> model = configureController(arm, weights, ControllerParams{});
  OdeArmBackend robot(model.arm, SimParams{}, ref.target.front());
  ControllerData<Dims> data;
  test::PolicyWithNan<Dims> policy(model, data, 100, 102);  // the non-finite action's path too
  SteadyClock clock;
  // Frames prepared before counting: dropouts of 5 s every 60 s (home-return path), NaN
  // keypoints every 97th tick.
  constexpr int kTicks = 6000;
  std::vector<SkeletonFrame> frames(kTicks);
  std::vector<bool> present(kTicks);
  for (int t = 0; t < kTicks; ++t) {
    const std::size_t i = static_cast<std::size_t>(t) % ref.frames.size();
    frames[static_cast<std::size_t>(t)] = ref.frames[i];
    if (t % 97 == 0) frames[static_cast<std::size_t>(t)].p_W[kRElbow].y() = std::nan("");
    present[static_cast<std::size_t>(t)] = ref.present[i] && (t % 600) < 550;
  }

  std::int64_t allocations = 0;
  std::uint32_t faults_seen = 0;
  {
    nao::test::CountAllocations count;
    activateOnRobot(model, data, robot, ref.target.front(), 1, clock);
    for (int t = 0; t < kTicks; ++t) {
      const std::size_t i = static_cast<std::size_t>(t);
      faults_seen |= runControllerTick(model, data, robot, present[i] ? &frames[i] : nullptr, policy).fault;
    }
    deactivateOnRobot(model, data, robot);
    allocations = count.count();
  }
  CHECK(allocations == 0);
  CHECK(data.tick == kTicks);
  // The fault paths ran inside the counted window.
  CHECK((faults_seen & kFaultNoHuman) != 0);
  CHECK((faults_seen & kFaultHumanBridged) != 0);
  CHECK((faults_seen & kFaultHumanTimeout) != 0);
  CHECK((faults_seen & kFaultNonFiniteKeypoints) != 0);
  CHECK((faults_seen & kFaultPolicyNonFinite) != 0);
}

}  // namespace

TEST_CASE("6,000 controller ticks with the small policy allocate nothing") { checkNoAllocation<SmallPolicyDims>(3); }

TEST_CASE("6,000 controller ticks with the paper policy allocate nothing") { checkNoAllocation<PaperPolicyDims>(4); }

TEST_CASE("6,000 controller ticks with a small policy of chunk 5 (the temporal ensemble) allocate nothing") {
  PolicyArch arch = SmallPolicyDims::arch();
  arch.chunk = 5;
  checkNoAllocation<SmallPolicyDims>(6, arch);
}

TEST_CASE("an autonomous run that chooses its run code at activate allocates nothing, and the code moves its actions") {
  using Dims = SmallPolicyDims;
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const test::RandomPolicy random = test::makeRandomPolicy(Dims::arch(), arm, 8);
  const PolicyWeights<Dims> weights =
      bindPolicyWeights<Dims>(random.pointers.data(), random.pointers.size(), Dims::arch(), Conditioning::kAutonomous);
  // 40 demonstrations per movement: starts around home, random codes, a symmetric DTW table.
  std::mt19937_64 rng(11);
  const auto uniform = [&](double lo, double hi) { return static_cast<double>(test::uniformFloat(rng, lo, hi)); };
  std::vector<ModelRunCodes> codes(static_cast<std::size_t>(weights.movements));
  for (ModelRunCodes& c : codes) {
    constexpr std::size_t n = 40;
    c.d = Dims::kDModel;
    for (std::size_t i = 0; i < n; ++i) {
      c.names.push_back("demo_" + std::to_string(i));
      c.q.push_back(ControllerParams{}.home + 0.3 * JointVector::NullaryExpr([&] { return uniform(-1.0, 1.0); }));
    }
    for (std::size_t i = 0; i < n * Dims::kDModel; ++i) c.code.push_back(static_cast<float>(uniform(-1.0, 1.0)));
    c.dtw_m.assign(n * n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t k = i + 1; k < n; ++k) c.dtw_m[i * n + k] = c.dtw_m[k * n + i] = uniform(0.0, 0.05);
  }
  const ControllerModel<Dims> with = configureController(arm, weights, ControllerParams{}, {}, codes);
  const ControllerModel<Dims> without = configureController(arm, weights, ControllerParams{});
  const JointVector start = ControllerParams{}.home + JointVector::Constant(0.05);
  constexpr int kTicks = 600;
  std::vector<JointVector> q_with, q_without;
  for (const ControllerModel<Dims>* model : {&with, &without}) {
    OdeArmBackend robot(model->arm, SimParams{}, start);
    ControllerData<Dims> data;
    SteadyClock clock;
    std::vector<JointVector>& q = model == &with ? q_with : q_without;
    q.resize(kTicks);
    std::int64_t allocations = 0;
    {
      nao::test::CountAllocations count;
      activateOnRobot(*model, data, robot, start, 1, clock);
      for (int t = 0; t < kTicks; ++t) q[static_cast<std::size_t>(t)] = runControllerTick(*model, data, robot, nullptr).q;
      deactivateOnRobot(*model, data, robot);
      allocations = count.count();
    }
    CHECK(allocations == 0);
    if (model == &with) {
      const int i = runCodeIndex(codes[1], clampToLimits(arm, start));
      REQUIRE(i >= 0);
      CHECK(data.run_code == i);
      for (int k = 0; k < Dims::kDModel; ++k)
        CHECK(data.policy->run_code[k] == codes[1].code[static_cast<std::size_t>(i * Dims::kDModel + k)]);
    } else {
      CHECK(data.run_code == -1);
      CHECK(data.policy->run_code.isZero(0.0f));
    }
  }
  double moved = 0.0;
  for (int t = 0; t < kTicks; ++t) moved = std::max(moved, (q_with[static_cast<std::size_t>(t)] - q_without[static_cast<std::size_t>(t)]).norm());
  CHECK(moved > 1e-3);
}
