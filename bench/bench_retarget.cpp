// Retargeting IK latency: the runtime's fixed-size LM against KDL's ChainIkSolverPos_LMA
// (position-only weights) and the offline Ceres version, on the same hand-position targets
// from the same start points (the q_x solve of Algorithm 1 without a joint target: start and
// displacement anchor = the previous frame's pose).
//
// Problems: 20 smooth joint-space trajectories at 10 Hz (per joint, two sines of 0.3-1.5 rad/s
// around the middle of the range, peak 45 % of the range), 100 frames each; target = FK of
// frame k, start = frame k-1. Precomputed before timing. Each benchmark iteration is one
// solve, timed on its own (manual time), so the counters give median and p99 per solve.
// Success = final hand error < 1 mm (our FK; checked outside the timed region).
#include "nao/retarget.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/tools/retarget_ceres.hpp"

#include <benchmark/benchmark.h>
#include <kdl/chain.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>
#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

using namespace nao;

struct IkProblem {
  Eigen::Vector3d p_target_TH;
  JointVector q_start;
};

const ArmModel& arm() {
  static const ArmModel model = loadArmModel(NAO_DEFAULT_URDF);
  return model;
}

const std::vector<IkProblem>& problems() {
  static const std::vector<IkProblem> set = [] {
    const ArmModel& m = arm();
    std::mt19937_64 rng(20261121);
    std::uniform_real_distribution<double> freq(0.3, 1.5), phase(0.0, 6.283185307179586), mix(0.3, 0.7);
    ArmData d;
    std::vector<IkProblem> out;
    for (int traj = 0; traj < 20; ++traj) {
      JointVector w1, w2, p1, p2, a;
      for (int j = 0; j < kNumJoints; ++j) {
        w1[j] = freq(rng);
        w2[j] = freq(rng);
        p1[j] = phase(rng);
        p2[j] = phase(rng);
        a[j] = mix(rng);
      }
      auto pose = [&](int k) {
        JointVector q;
        for (int j = 0; j < kNumJoints; ++j) {
          const double mid = 0.5 * (m.q_min[j] + m.q_max[j]), range = m.q_max[j] - m.q_min[j];
          const double t = 0.1 * k;
          q[j] = mid + 0.45 * range * (a[j] * std::sin(w1[j] * t + p1[j]) + (1.0 - a[j]) * std::sin(w2[j] * t + p2[j]));
        }
        return q;
      };
      for (int k = 1; k <= 100; ++k) out.push_back({forwardKinematics(m, d, pose(k)), pose(k - 1)});
    }
    return out;
  }();
  return set;
}

// Per-solve timing and success bookkeeping shared by the three benchmarks.
struct Record {
  std::vector<double> us;
  int n_ok = 0;
  int n_inside = 0;
  int n = 0;
  ArmData d;

  void add(const ArmModel& m, const IkProblem& p, const JointVector& q, double seconds) {
    us.push_back(seconds * 1e6);
    n_ok += (forwardKinematics(m, d, q) - p.p_target_TH).norm() < 1e-3;
    n_inside += (q.array() >= m.q_min.array()).all() && (q.array() <= m.q_max.array()).all();
    ++n;
  }

  void report(benchmark::State& state) {
    if (us.empty()) return;
    std::sort(us.begin(), us.end());
    const auto at = [&](double f) { return us[std::min(us.size() - 1, static_cast<std::size_t>(f * static_cast<double>(us.size())))]; };
    state.counters["p50_us"] = at(0.50);
    state.counters["p99_us"] = at(0.99);
    state.counters["success"] = static_cast<double>(n_ok) / n;
    state.counters["in_limits"] = static_cast<double>(n_inside) / n;
  }
};

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

void BM_Retarget_NaoLM(benchmark::State& state) {
  const ArmModel& m = arm();
  const std::vector<IkProblem>& set = problems();
  const RetargetParams params;
  RetargetData data;
  Record rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const IkProblem& p = set[i++ % set.size()];
    const Clock::time_point t0 = Clock::now();
    const JointVector& q = solveHandIk(m, params, data, p.p_target_TH, p.q_start, p.q_start);
    benchmark::DoNotOptimize(q.data());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(m, p, q, s);
  }
  rec.report(state);
}

void BM_Retarget_KdlLMA(benchmark::State& state) {
  const ArmModel& m = arm();
  const std::vector<IkProblem>& set = problems();
  KDL::Tree tree;
  KDL::Chain chain;
  if (!kdl_parser::treeFromFile(NAO_DEFAULT_URDF, tree) || !tree.getChain(kTorsoLink, kHandLink, chain)) {
    state.SkipWithError("KDL could not read the URDF chain torso -> r_hand");
    return;
  }
  Eigen::Matrix<double, 6, 1> L;
  L << 1.0, 1.0, 1.0, 0.0, 0.0, 0.0;  // position only
  KDL::ChainIkSolverPos_LMA solver(chain, L);  // KDL defaults: eps 1e-5, 500 iterations
  KDL::JntArray q_init(kNumJoints), q_out(kNumJoints);
  Record rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const IkProblem& p = set[i++ % set.size()];
    for (int j = 0; j < kNumJoints; ++j) q_init(j) = p.q_start[j];
    const KDL::Frame target(KDL::Vector(p.p_target_TH.x(), p.p_target_TH.y(), p.p_target_TH.z()));
    const Clock::time_point t0 = Clock::now();
    const int rc = solver.CartToJnt(q_init, target, q_out);
    benchmark::DoNotOptimize(rc);
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j) q[j] = q_out(j);
    rec.add(m, p, q, s);
  }
  rec.report(state);
}

void BM_Retarget_Ceres(benchmark::State& state) {
  const ArmModel& m = arm();
  const std::vector<IkProblem>& set = problems();
  const RetargetParams params;
  tools::CeresRetargetData data;
  Record rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const IkProblem& p = set[i++ % set.size()];
    const Clock::time_point t0 = Clock::now();
    const JointVector& q = tools::solveHandIkCeres(m, params, data, p.p_target_TH, p.q_start, p.q_start);
    benchmark::DoNotOptimize(q.data());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(m, p, q, s);
  }
  rec.report(state);
}

// Whole frames of Algorithm 1 (q_x and q_q) online, for the per-tick budget; not a peer race.
void BM_Retarget_NaoAlgorithm1Frame(benchmark::State& state) {
  const ArmModel& m = arm();
  const std::vector<IkProblem>& set = problems();
  const RetargetParams params;
  RetargetData data;
  Record rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const IkProblem& p = set[i++ % set.size()];
    // Joint target: the start pose shifted by 0.2 rad (a human posture the hand target
    // does not exactly match).
    const JointVector q_target = p.q_start.array() + 0.2;
    if (i % 100 == 1) resetRetarget(data);
    const Clock::time_point t0 = Clock::now();
    const RetargetResult& r = solveRetarget(m, params, data, p.p_target_TH, q_target);
    benchmark::DoNotOptimize(r.q_q.data());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(m, p, r.q_x, s);
  }
  rec.report(state);
}

}  // namespace

// Iterations fixed at a multiple of the problem count so every benchmark sees the same set.
BENCHMARK(BM_Retarget_NaoLM)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(20000);
BENCHMARK(BM_Retarget_KdlLMA)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(20000);
BENCHMARK(BM_Retarget_Ceres)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(4000);
BENCHMARK(BM_Retarget_NaoAlgorithm1Frame)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(4000);

BENCHMARK_MAIN();
