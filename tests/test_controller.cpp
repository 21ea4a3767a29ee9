// The 10 Hz controller as a hardware-in-the-loop substitute: it drives the ODE arm exactly as it
// would drive the robot. Behaviour around the policy (faults, limits, determinism) is tested
// here with a random small policy; imitation quality with trained models elsewhere.
#include "nao/controller.hpp"
#include "nao/robot_loop.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/kmeans.hpp"
#include "support/policy_faults.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <vector>

using namespace nao;
using Dims = SmallPolicyDims;

namespace {

// Counter index of kFaultHumanBridged (fault counters are indexed by bit).
constexpr std::size_t kBridgedBit = 14;
static_assert(kFaultHumanBridged == (1u << kBridgedBit), "human_bridged moved: update kBridgedBit");

// Deterministic clock: 1 µs per reading, plus a jump at a chosen reading.
struct FakeClock final : ControllerClock {
  std::int64_t now = 0;
  std::int64_t jump_at_reading = -1, jump_ns = 0, readings = 0;
  std::int64_t nowNs() override {
    if (readings++ == jump_at_reading) now += jump_ns;
    return now += 1000;
  }
};

struct Fixture {
  ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  test::RandomPolicy random = test::makeRandomPolicy(Dims::arch(), arm, 5);
  PolicyWeights<Dims> weights =
      bindPolicyWeights<Dims>(random.pointers.data(), random.pointers.size(), Dims::arch(),
                              Conditioning::kReference);
  tools::ReferenceStream ref;
  Fixture() {
    std::vector<JointVector> centroids;
    for (int k = 0; k < weights.clusters; ++k) centroids.push_back(centroid(weights, 0, k).cast<double>());
    ref = tools::makeSyntheticReference(arm, tools::Movement::kElbow, 1, 0, centroids);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

struct Run {
  std::vector<TickRecord> records;
  std::array<std::int64_t, kNumControllerFaults> faults{};
};

// Runs the reference once; `drop(tick)` true removes the human from that tick, `corrupt` puts
// NaN into the right shoulder of that tick's frame, `nan_ticks` (first, last) puts NaN into the
// policy's action on those ticks.
template <class Drop, class Corrupt>
Run run(const ControllerParams& params, FakeClock& clock, Drop drop, Corrupt corrupt, int n_ticks = -1,
        std::array<int, 2> nan_ticks = {-1, -1}) {
  Fixture& f = fixture();
  const ControllerModel<Dims> model = configureController(f.arm, f.weights, params);
  OdeArmBackend robot(model.arm, SimParams{}, f.ref.target.front());
  ControllerData<Dims> data;
  test::PolicyWithNan<Dims> nan_policy(model, data, nan_ticks[0], nan_ticks[1]);
  activateOnRobot(model, data, robot, f.ref.target.front(), 0, clock);
  Run r;
  const int n = n_ticks > 0 ? n_ticks : static_cast<int>(f.ref.frames.size());
  SkeletonFrame frame;
  for (int t = 0; t < n; ++t) {
    const std::size_t i = static_cast<std::size_t>(t) % f.ref.frames.size();
    frame = f.ref.frames[i];
    if (corrupt(t)) frame.p_W[kRShoulder].x() = std::nan("");
    const bool present = f.ref.present[i] && !drop(t);
    const SkeletonFrame* seen = present ? &frame : nullptr;
    r.records.push_back(nan_ticks[0] >= 0 ? runControllerTick(model, data, robot, seen, nan_policy)
                                          : runControllerTick(model, data, robot, seen));
  }
  deactivateOnRobot(model, data, robot);
  r.faults = data.fault_counts;
  return r;
}

auto never = [](int) { return false; };

bool insideLimits(const ArmModel& arm, const JointVector& q, double margin) {
  for (int j = 0; j < kNumJoints; ++j)
    if (q[j] < arm.q_min[j] - margin || q[j] > arm.q_max[j] + margin) return false;
  return true;
}

}  // namespace

TEST_CASE("the controller keeps every command inside the URDF limits and the measured arm within the sim's margin") {
  FakeClock clock;
  const Run r = run(ControllerParams{}, clock, never, never);
  const ArmModel& arm = fixture().arm;
  REQUIRE(r.records.size() > 50);
  for (const TickRecord& t : r.records) {
    CHECK(insideLimits(arm, t.q_cmd, 0.0));
    // The servo law keeps the joints inside the limits; allow ODE's constraint slack.
    CHECK(insideLimits(arm, t.q, 1e-3));
  }
  // And every command is reachable in one period at the velocity limits.
  for (std::size_t i = 1; i < r.records.size(); ++i)
    for (int j = 0; j < kNumJoints; ++j)
      CHECK(std::abs(r.records[i].q_cmd[j] - r.records[i - 1].q[j]) <= arm.v_max[j] * 0.1 + 1e-12);
}

TEST_CASE("two runs with the same inputs give bitwise-equal tick records") {
  FakeClock c1, c2;
  const Run a = run(ControllerParams{}, c1, never, never);
  const Run b = run(ControllerParams{}, c2, never, never);
  REQUIRE(a.records.size() == b.records.size());
  for (std::size_t i = 0; i < a.records.size(); ++i) {
    CHECK(std::memcmp(a.records[i].q.data(), b.records[i].q.data(), sizeof(double) * kNumJoints) == 0);
    CHECK(std::memcmp(a.records[i].a.data(), b.records[i].a.data(), sizeof(double) * kNumJoints) == 0);
    CHECK(std::memcmp(a.records[i].att.data(), b.records[i].att.data(), sizeof(float) * kNumJoints) == 0);
    CHECK(a.records[i].fault == b.records[i].fault);
  }
}

TEST_CASE("a 2 s reference dropout mid-movement holds the last reference, is counted, and the run recovers") {
  FakeClock clock;
  const int first = 30, last = 49;  // 20 ticks = 2 s
  const Run r = run(ControllerParams{}, clock, [&](int t) { return t >= first && t <= last; }, never);
  const Run clean = [&] {
    FakeClock c;
    return run(ControllerParams{}, c, never, never);
  }();
  REQUIRE(r.records.size() > static_cast<std::size_t>(last + 10));
  // Every dropped tick is flagged: the first two after the last human as bridged, the rest as
  // no_human; none reaches the home-return timeout (3 s).
  constexpr std::uint32_t kMissing = kFaultNoHuman | kFaultHumanBridged;
  int last_human = first - 1;
  while (r.records[static_cast<std::size_t>(last_human)].fault & kMissing) --last_human;
  for (int t = first; t <= last; ++t) {
    const TickRecord& rec = r.records[static_cast<std::size_t>(t)];
    const bool bridged = t - last_human <= 2;
    CHECK(((rec.fault & kFaultHumanBridged) != 0) == bridged);
    CHECK(((rec.fault & kFaultNoHuman) != 0) == !bridged);
    CHECK((rec.fault & kFaultHumanTimeout) == 0);
    CHECK(rec.q_ref == r.records[static_cast<std::size_t>(first - 1)].q_ref);
  }
  // Counted once per dropped tick (ticks the synthesiser had already dropped count once).
  int newly_dropped = 0;
  for (int t = first; t <= last; ++t) newly_dropped += (clean.records[static_cast<std::size_t>(t)].fault & kMissing) ? 0 : 1;
  CHECK(newly_dropped > 10);
  CHECK(r.faults[0] + r.faults[kBridgedBit] - clean.faults[0] - clean.faults[kBridgedBit] == newly_dropped);
  CHECK(r.faults[1] == 0);
  // After the dropout the reference follows the human again.
  bool moved = false;
  for (std::size_t t = last + 1; t < r.records.size(); ++t)
    moved = moved || r.records[t].q_ref != r.records[static_cast<std::size_t>(first - 1)].q_ref;
  CHECK(moved);
}

TEST_CASE("a dropout longer than the timeout sends the arm home at half speed, bypassing the policy") {
  FakeClock clock;
  ControllerParams params;
  params.no_human_timeout_s = 1.0;
  const int first = 10;
  const Run r = run(params, clock, [&](int t) { return t >= first; }, never, 120);
  const ArmModel& arm = fixture().arm;
  const JointVector home = clampToLimits(arm, params.home);
  int timeouts = 0;
  for (std::size_t t = first; t < r.records.size(); ++t) {
    const TickRecord& rec = r.records[t];
    // Timeout once more than 1 s has passed since the last human (tick first - 1).
    const bool expected = static_cast<double>(static_cast<int>(t) - (first - 1)) * 0.1 > 1.0 + 1e-9;
    CHECK(((rec.fault & kFaultHumanTimeout) != 0) == expected);
    if (!expected) continue;
    ++timeouts;
    for (int j = 0; j < kNumJoints; ++j) CHECK(std::abs(rec.a[j]) <= 0.5 * arm.v_max[j] * 0.1 + 1e-12);
  }
  CHECK(timeouts == r.faults[1]);
  CHECK(timeouts > 50);
  // 10 s later the arm is home (within the servo's settling).
  CHECK((r.records.back().q - home).cwiseAbs().maxCoeff() < 0.02);
}

TEST_CASE("NaN keypoints are counted as a fault, treated as no human, and the run continues") {
  FakeClock clock;
  ControllerParams params;
  params.human_bridge_ticks = 0;  // no_human at once (the bridge has its own test)
  const Run r = run(params, clock, never, [](int t) { return t == 20 || t == 21; });
  for (int t : {20, 21}) {
    const TickRecord& rec = r.records[static_cast<std::size_t>(t)];
    CHECK((rec.fault & kFaultNonFiniteKeypoints) != 0);
    CHECK((rec.fault & kFaultNoHuman) != 0);
    CHECK(rec.q_ref.allFinite());
    CHECK(rec.q_cmd.allFinite());
  }
  CHECK(r.faults[2] == 2);
  CHECK(r.records.back().q.allFinite());
}

TEST_CASE("a non-finite policy output holds the position and is counted") {
  FakeClock clock;
  const Run r = run(ControllerParams{}, clock, never, never, -1, {15, 17});
  for (int t = 15; t <= 17; ++t) {
    const TickRecord& rec = r.records[static_cast<std::size_t>(t)];
    CHECK((rec.fault & kFaultPolicyNonFinite) != 0);
    CHECK(rec.a == JointVector::Zero());
    // Hold position: the command is where the arm was at the start of the tick.
    CHECK(rec.q_cmd == r.records[static_cast<std::size_t>(t - 1)].q);
  }
  CHECK(r.faults[4] == 3);
  CHECK(r.records.size() == fixture().ref.frames.size());
}

TEST_CASE("an overrun forced through the injected clock is counted once and the loop continues") {
  FakeClock clock;
  // Five readings per tick on a robot (four in updateController, one in finishTick): a 150 ms
  // jump inside tick 7's policy stage.
  clock.jump_at_reading = 7 * 5 + 2;
  clock.jump_ns = 150'000'000;
  const Run r = run(ControllerParams{}, clock, never, never);
  CHECK(r.faults[5] == 1);
  CHECK((r.records[7].fault & kFaultOverrun) != 0);
  CHECK(r.records[7].policy_us > 1e5);
  CHECK(r.records.size() == fixture().ref.frames.size());
}

TEST_CASE("updateController needs no robot: read, update, write and finishTick by hand are runControllerTick bit for bit") {
  Fixture& f = fixture();
  const ControllerModel<Dims> model = configureController(f.arm, f.weights, ControllerParams{});
  OdeArmBackend a(model.arm, SimParams{}, f.ref.target.front()), b(model.arm, SimParams{}, f.ref.target.front());
  ControllerData<Dims> da, db;
  FakeClock ca, cb;
  activateOnRobot(model, da, a, f.ref.target.front(), 0, ca);
  activateController(model, db, b.activate(clampToLimits(model.arm, f.ref.target.front())), 0, cb);
  for (std::size_t i = 0; i < f.ref.frames.size(); ++i) {
    const SkeletonFrame* frame = f.ref.present[i] ? &f.ref.frames[i] : nullptr;
    const TickRecord& ra = runControllerTick(model, da, a, frame);
    const JointVector q_start = b.measured();
    const TickRecord& rb = updateController(model, db, q_start, frame);
    // The pure update: the command, the record's q still the start, no hand point yet.
    CHECK(rb.q == q_start);
    CHECK(std::isnan(rb.ee.x()));
    CHECK(rb.q_cmd == ra.q_cmd);
    const JointVector& q_end = b.command(rb.q_cmd);
    finishTick(model, db, q_end, b.faults(), b.waitNs());
    CHECK(std::memcmp(ra.q.data(), rb.q.data(), sizeof(double) * kNumJoints) == 0);
    CHECK(std::memcmp(ra.ee.data(), rb.ee.data(), sizeof(double) * 3) == 0);
    CHECK(std::memcmp(ra.att.data(), rb.att.data(), sizeof(float) * kNumJoints) == 0);
    CHECK(ra.fault == rb.fault);
    CHECK(ra.tick_us == rb.tick_us);
    CHECK(ra.sim_us == rb.sim_us);
  }
  CHECK(da.fault_counts == db.fault_counts);
}

TEST_CASE("the synthetic reference is not a training demonstration and has a target for every tick") {
  const tools::ReferenceStream& ref = fixture().ref;
  CHECK(ref.description.find("seed 1000001") != std::string::npos);
  CHECK(ref.target.size() == ref.frames.size());
  CHECK(ref.retargeted.size() == ref.frames.size());
  int measured = 0;
  for (bool m : ref.measured) measured += m ? 1 : 0;
  CHECK(measured > static_cast<int>(ref.frames.size()) / 2);
}

TEST_CASE("detector gaps of up to 2 ticks are bridged on the held reference; from the 3rd tick on they are no_human") {
  FakeClock clock;
  // Gaps of 1, 2 and 3 ticks after stretches with the human, and none before the first human.
  auto gap = [](int t) { return t == 20 || t == 30 || t == 31 || (t >= 40 && t <= 42); };
  const Run r = run(ControllerParams{}, clock, gap, never);
  FakeClock c0;
  ControllerParams off;
  off.human_bridge_ticks = 0;
  const Run unbridged = run(off, c0, gap, never);
  REQUIRE(r.records.size() == unbridged.records.size());
  for (int t : {20, 30, 31, 40, 41, 42}) {
    const TickRecord& rec = r.records[static_cast<std::size_t>(t)];
    // The synthesiser's reference has gaps of its own: count from the last tick with a human.
    int last_human = t - 1;
    while (r.records[static_cast<std::size_t>(last_human)].fault & (kFaultNoHuman | kFaultHumanBridged)) --last_human;
    const bool bridged = t - last_human <= 2;
    INFO("tick " << t << ", last human " << last_human);
    CHECK(((rec.fault & kFaultHumanBridged) != 0) == bridged);
    CHECK(((rec.fault & kFaultNoHuman) != 0) == !bridged);
    // Held: the reference of the last tick with a human.
    CHECK(rec.q_ref == r.records[static_cast<std::size_t>(t) - 1].q_ref);
    // Only the label differs from the unbridged run: the arm does the same.
    CHECK(rec.q_cmd == unbridged.records[static_cast<std::size_t>(t)].q_cmd);
    CHECK(((unbridged.records[static_cast<std::size_t>(t)].fault & kFaultNoHuman) != 0));
  }
  CHECK((r.records[42].fault & kFaultNoHuman) != 0);  // a 3-tick gap is no_human from its 3rd tick
  // Bridged ticks are not no_human ticks: the counts move from one bit to the other.
  CHECK(r.faults[kBridgedBit] > 0);
  CHECK(r.faults[0] + r.faults[kBridgedBit] == unbridged.faults[0]);
  CHECK(unbridged.faults[kBridgedBit] == 0);
  // Before the first human there is nothing to bridge.
  FakeClock c1;
  const Run late = run(ControllerParams{}, c1, [](int t) { return t < 2; }, never, 5);
  CHECK((late.records[0].fault & kFaultNoHuman) != 0);
  CHECK((late.records[1].fault & kFaultNoHuman) != 0);
}

TEST_CASE("the reference-mode policy is fed the feature-extracted target f(t+1) of the snapped key poses, as the toolchain makes it") {
  // Online (controller) and offline (toolchain featureTrajectory) blends of the same key-pose
  // sequence: after tick t the controller's f is the offline f(t+1).
  Fixture& f = fixture();
  FakeClock clock;
  const ControllerModel<Dims> model = configureController(f.arm, f.weights, ControllerParams{});
  OdeArmBackend robot(model.arm, SimParams{}, f.ref.target.front());
  ControllerData<Dims> data;
  activateOnRobot(model, data, robot, f.ref.target.front(), 0, clock);
  std::vector<JointVector> online, keys;
  std::vector<double> t_s;
  for (std::size_t i = 0; i < f.ref.frames.size(); ++i) {
    const TickRecord& rec = runControllerTick(model, data, robot, f.ref.present[i] ? &f.ref.frames[i] : nullptr);
    online.push_back(data.feature_f);
    keys.push_back(rec.r);
    t_s.push_back(0.1 * static_cast<double>(i));
  }
  deactivateOnRobot(model, data, robot);
  keys.push_back(keys.back());
  t_s.push_back(0.1 * static_cast<double>(keys.size() - 1));
  std::vector<JointVector> centroids;
  for (int k = 0; k < f.weights.clusters; ++k) centroids.push_back(centroid(f.weights, 0, k).cast<double>());
  const std::vector<JointVector> offline = tools::featureTrajectory(centroids, t_s, keys);
  REQUIRE(offline.size() == online.size() + 1);
  double worst = 0.0, moved = 0.0;
  for (std::size_t t = 0; t < online.size(); ++t) {
    worst = std::max(worst, (online[t] - offline[t + 1]).cwiseAbs().maxCoeff());
    moved = std::max(moved, (online[t] - online.front()).cwiseAbs().maxCoeff());
  }
  CHECK(worst < 1e-12);
  CHECK(moved > 0.05);  // not vacuous: the key poses change and the blend follows
}
