// Attention ring: what a reader costs the writer (readers must never slow the writer).
//
// Every benchmark pushes one paper-size record (AttentionPayload<4, 4, 128, 20>, 4304 bytes) per
// iteration into the default 1024-slot ring (4.3 MB: the writer walks through it like the
// controller, one slot per tick). The *_HammeringReader variants run a second thread that reads
// the newest record with readFromNonRT in a tight loop, the worst reader there is. Counters:
// reader_reads per iteration, reader_ok = fraction of its reads that returned an intact record.
//
// BM_RingPush_*: pushFromRT alone at tick pace: one push per kTickPeriod (spin-waited outside
//   the timing, so the writer's cache stays warm: the least favourable baseline), each push
//   timed on its own (manual time, steady_clock; p50_ns/p99_ns). The writer never waits for
//   the reader, but it pays cache coherence for being read: the slot lines and the count the
//   reader copied must be taken back from it when they are written again.
// BM_RingTick_*: the claim ("a reader never slows the writer's tick by more than 5 %") on a
//   stand-in for the tick: one online retarget frame (Algorithm 1, part of every tick), then
//   the record filled, sealed and pushed, back to back. A lower bound on the real tick (no
//   policy inference, no 100 ODE steps), so the ratio it shows is an upper bound.
// BM_RingTick_BusyNeighbour: control for the tick pair: the second thread copies 4 KB of its
//   own memory in a loop and never touches the ring, which shows what a busy second core costs
//   the tick on this machine (shared caches, a hypervisor's sibling threads) without the ring.
// BM_RingPushBackToBack_*: saturation, not the controller's regime: pushes with nothing in
//   between (~8 million a second, against 10 in the controller), so the reader keeps pulling
//   freshly written lines out of the writer's caches while it writes the next slot.
//
// On a 2-core machine the reader needs the second core to itself: run on an idle machine or
// under SCHED_FIFO (as the controller does), with repetitions, and compare medians:
//   chrt -f 10 nao_bench --benchmark_filter='BM_Ring' --benchmark_repetitions=10
//     --benchmark_enable_random_interleaving=true --benchmark_report_aggregates_only=true
#include "nao/attention_ring.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/kinematics.hpp"
#include "nao/retarget.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdint>
#include <memory>
#include <random>
#include <thread>
#include <vector>

namespace {

using PaperPayload = nao::AttentionPayload<4, 4, 128, 20>;
using PaperRing = nao::AttentionRing<PaperPayload>;
using Clock = std::chrono::steady_clock;

// Far longer than a push (~0.1-0.2 us) and short enough for 20,000 pushes a second: stands in
// for the controller's 100 ms tick.
constexpr std::chrono::microseconds kTickPeriod{50};
constexpr int kPacedPushes = 20000;

// One ring for every benchmark, built (and its pages faulted in) before any timing.
PaperRing& ring() {
  static const std::unique_ptr<PaperRing> r = std::make_unique<PaperRing>(nao::attentionPayloadDescriptor<PaperPayload>());
  return *r;
}

const PaperPayload& payload() {
  static const PaperPayload p = [] {
    PaperPayload q;
    for (int j = 0; j < PaperPayload::kTokens; ++j) q.score[j] = 0.2f * static_cast<float>(j);
    q.cross_out[1][2] = 1.5f;
    nao::sealPayload(q);
    return q;
  }();
  return p;
}

// The worst reader: the newest record, again and again, as fast as it can.
class HammeringReader {
 public:
  HammeringReader() : thread_([this] { run(); }) {
    while (!started_.load()) std::this_thread::yield();
  }
  HammeringReader(const HammeringReader&) = delete;
  HammeringReader& operator=(const HammeringReader&) = delete;

  // Stops the thread and reports its counters against the writer's iterations.
  void finish(benchmark::State& state) {
    stop_.store(true);
    thread_.join();
    state.counters["reader_reads"] = benchmark::Counter(static_cast<double>(reads_), benchmark::Counter::kAvgIterations);
    state.counters["reader_ok"] = reads_ > 0 ? static_cast<double>(ok_) / static_cast<double>(reads_) : 0.0;
  }

 private:
  void run() {
    auto out = std::make_unique<PaperPayload>();
    const PaperRing& r = ring();
    started_.store(true);
    while (!stop_.load(std::memory_order_relaxed)) {
      const auto latest = nao::latestRecord(r);
      if (!latest) continue;
      ++reads_;
      ok_ += nao::readFromNonRT(r, *latest, *out) == nao::AttentionRead::kOk;
      benchmark::DoNotOptimize(out->tick);
    }
  }

  std::atomic<bool> stop_{false}, started_{false};
  std::int64_t reads_ = 0, ok_ = 0;
  std::thread thread_;  // last: starts after the fields it uses exist
};

void pacedPushes(benchmark::State& state) {
  PaperRing& r = ring();
  const PaperPayload& p = payload();
  std::vector<double> ns;
  ns.reserve(kPacedPushes);
  Clock::time_point next = Clock::now();
  for (auto _ : state) {
    next += kTickPeriod;
    while (Clock::now() < next) {
    }
    const Clock::time_point t0 = Clock::now();
    benchmark::DoNotOptimize(nao::pushFromRT(r, p));
    benchmark::ClobberMemory();
    const Clock::time_point t1 = Clock::now();
    const double s = std::chrono::duration<double>(t1 - t0).count();
    state.SetIterationTime(s);
    ns.push_back(s * 1e9);
  }
  std::sort(ns.begin(), ns.end());
  const auto at = [&](double f) { return ns[std::min(ns.size() - 1, static_cast<std::size_t>(f * static_cast<double>(ns.size())))]; };
  state.counters["p50_ns"] = at(0.50);
  state.counters["p99_ns"] = at(0.99);
}

void backToBackPushes(benchmark::State& state) {
  PaperRing& r = ring();
  const PaperPayload& p = payload();
  for (auto _ : state) {
    benchmark::DoNotOptimize(nao::pushFromRT(r, p));
    benchmark::ClobberMemory();
  }
}

// The tick stand-in's inputs: a smooth 10 Hz joint trajectory (per joint a sine around the
// middle of the range), hand targets = its FK, joint targets = the poses shifted by 0.2 rad
// (as BM_Retarget_NaoAlgorithm1Frame), and the "policy's" attention numbers for the record.
struct TickInputs {
  nao::ArmModel arm = nao::loadArmModel(NAO_DEFAULT_URDF);
  std::vector<Eigen::Vector3d> p_targets_TH;
  std::vector<nao::JointVector> q_targets;
  PaperPayload attention;
};

const TickInputs& tickInputs() {
  static const std::unique_ptr<TickInputs> in = [] {
    auto t = std::make_unique<TickInputs>();
    std::mt19937_64 rng(20261122);
    nao::ArmData d;
    std::uniform_real_distribution<double> freq(0.3, 1.5);
    nao::JointVector w;
    for (int j = 0; j < nao::kNumJoints; ++j) w[j] = freq(rng);
    for (int i = 0; i < 1000; ++i) {
      nao::JointVector q;
      for (int j = 0; j < nao::kNumJoints; ++j) {
        const double mid = 0.5 * (t->arm.q_min[j] + t->arm.q_max[j]);
        const double range = t->arm.q_max[j] - t->arm.q_min[j];
        q[j] = mid + 0.45 * range * std::sin(w[j] * 0.1 * i);
      }
      t->p_targets_TH.push_back(nao::forwardKinematics(t->arm, d, q));
      t->q_targets.push_back(q.array() + 0.2);
    }
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (auto& l : t->attention.cross)
      for (auto& h : l)
        for (auto& i : h)
          for (float& v : i) v = u(rng);
    for (auto& i : t->attention.cross_out)
      for (float& v : i) v = u(rng);
    return t;
  }();
  return *in;
}

void ticks(benchmark::State& state) {
  const TickInputs& in = tickInputs();
  const nao::RetargetParams params;
  nao::RetargetData data;
  auto record = std::make_unique<PaperPayload>();
  PaperRing& r = ring();
  std::uint64_t tick = 0;
  for (auto _ : state) {
    const std::size_t k = tick % in.q_targets.size();
    const nao::RetargetResult& res = nao::solveRetarget(in.arm, params, data, in.p_targets_TH[k], in.q_targets[k]);
    // What the controller does with the policy's attention record each tick.
    record->tick = tick;
    record->fault = res.flags;
    for (int j = 0; j < PaperPayload::kTokens; ++j) record->score[j] = static_cast<float>(res.q_q[j]);
    std::memcpy(record->cross, in.attention.cross, sizeof record->cross);
    std::memcpy(record->cross_out, in.attention.cross_out, sizeof record->cross_out);
    nao::sealPayload(*record);
    benchmark::DoNotOptimize(nao::pushFromRT(r, *record));
    ++tick;
  }
}

void BM_RingPush_NoReader(benchmark::State& state) { pacedPushes(state); }

void BM_RingPush_HammeringReader(benchmark::State& state) {
  HammeringReader reader;
  pacedPushes(state);
  reader.finish(state);
}

void BM_RingTick_NoReader(benchmark::State& state) { ticks(state); }

void BM_RingTick_HammeringReader(benchmark::State& state) {
  HammeringReader reader;
  ticks(state);
  reader.finish(state);
}

void BM_RingTick_BusyNeighbour(benchmark::State& state) {
  std::atomic<bool> stop{false};
  std::thread neighbour([&stop] {
    std::vector<unsigned char> from(sizeof(PaperPayload)), to(sizeof(PaperPayload));
    while (!stop.load(std::memory_order_relaxed)) {
      std::memcpy(to.data(), from.data(), to.size());
      benchmark::DoNotOptimize(to.data());
    }
  });
  ticks(state);
  stop.store(true);
  neighbour.join();
}

void BM_RingPushBackToBack_NoReader(benchmark::State& state) { backToBackPushes(state); }

void BM_RingPushBackToBack_HammeringReader(benchmark::State& state) {
  HammeringReader reader;
  backToBackPushes(state);
  reader.finish(state);
}

}  // namespace

BENCHMARK(BM_RingPush_NoReader)->UseManualTime()->Unit(benchmark::kNanosecond)->Iterations(kPacedPushes);
BENCHMARK(BM_RingPush_HammeringReader)->UseManualTime()->Unit(benchmark::kNanosecond)->Iterations(kPacedPushes);
BENCHMARK(BM_RingTick_NoReader)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_RingTick_HammeringReader)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_RingTick_BusyNeighbour)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_RingPushBackToBack_NoReader)->Unit(benchmark::kNanosecond);
BENCHMARK(BM_RingPushBackToBack_HammeringReader)->Unit(benchmark::kNanosecond);
