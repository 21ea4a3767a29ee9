// The trainer's closed-loop rollout (toolchain/src/torch/closed_loop.hpp), per rolled tick: the net
// streamed with its key/value caches (streamStep) through the command limiter and the arm copy
// (armCopyTick), forward and backward, for a batch of runs; beside the same rollout without a
// cache, where each tick reruns the sequence forward over every tick so far (what a rollout
// would cost through PolicyNetImpl::act). Small and paper configurations, random weights, one
// thread.
#include "arm_copy_torch.hpp"
#include "nao/arm_model.hpp"
#include "policy_stream.hpp"
#include "policy_torch.hpp"

#include <benchmark/benchmark.h>
#include <torch/torch.h>

namespace {

using namespace nao;
using namespace nao::tools;

const SimModel& benchSim() {
  static const SimModel sim = makeSimModel(loadArmModel(NAO_DEFAULT_URDF));
  return sim;
}

PolicyNet benchNet(bool paper) {
  torch::manual_seed(1);
  PolicyArch arch = paper ? paperArch() : smallArch();
  arch.chunk = 10;
  PolicyNet net(arch, Conditioning::kAutonomous);
  torch::NoGradGuard no_grad;
  for (torch::Tensor& p : net->trainableParameters()) p.add_(torch::randn_like(p) * 0.02);
  net->setEnsembleDecay(0.0);
  return net;
}

// One rollout of T ticks for B runs from rest at the middle of the range, loss on the hand, backward.
void rollout(const PolicyNet& net, std::int64_t B, std::int64_t T, bool cached) {
  const SimModel& sim = benchSim();
  JointVector mid = 0.5 * (sim.arm.q_min + sim.arm.q_max);
  torch::Tensor q = torch::empty({B, kNumJoints}, torch::kFloat64);
  for (int j = 0; j < kNumJoints; ++j) q.select(1, j).fill_(mid[j]);
  torch::Tensor v = torch::zeros_like(q), a_prev = torch::zeros({B, kNumJoints});
  const torch::Tensor lo = torch::full({B, kNumJoints}, -10.0, torch::kFloat64), hi = -lo;
  const torch::Tensor movement = torch::zeros({B}, torch::kInt64);
  PolicyStream stream;
  std::vector<torch::Tensor> qs, as;
  torch::Tensor loss = torch::zeros({}, torch::kFloat64);
  for (std::int64_t t = 0; t < T; ++t) {
    torch::Tensor a;
    if (cached) {
      StreamInput in;
      in.q = q.to(torch::kFloat32);
      in.a_prev = a_prev;
      in.movement = movement;
      in.step = torch::full({B}, t, torch::kInt64);
      a = streamStep(*net, stream, in);
    } else {
      qs.push_back(q.to(torch::kFloat32));
      as.push_back(a_prev);
      const torch::Tensor qq = torch::stack(qs, 1), aa = torch::stack(as, 1);
      a = net->act(qq, aa, torch::zeros_like(qq), movement).select(1, t);
    }
    const ArmTick k = armCopyTick(sim, 0.1, q, v, a, lo, hi);
    loss = loss + k.hand.square().sum();
    q = k.q;
    v = k.v;
    a_prev = k.a_applied.to(torch::kFloat32);
  }
  loss.backward();
}

void BM_ClosedLoop(benchmark::State& state, bool cached, bool paper = false) {
  torch::set_num_threads(1);
  const PolicyNet net = benchNet(paper);
  const std::int64_t B = state.range(0), T = state.range(1);
  for (auto _ : state) {
    for (auto& p : net->parameters()) p.mutable_grad() = torch::Tensor();
    rollout(net, B, T, cached);
  }
  state.counters["ms_per_tick"] =
      benchmark::Counter(static_cast<double>(T) * 1e-3, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_ClosedLoop_Streamed(benchmark::State& state) { BM_ClosedLoop(state, true); }
void BM_ClosedLoop_Recomputed(benchmark::State& state) { BM_ClosedLoop(state, false); }
void BM_ClosedLoop_Streamed_Paper(benchmark::State& state) { BM_ClosedLoop(state, true, true); }

}  // namespace

BENCHMARK(BM_ClosedLoop_Streamed)->Args({16, 30})->Args({64, 30})->Args({16, 150})->Args({64, 150})->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_ClosedLoop_Streamed_Paper)->Args({16, 30})->Args({16, 150})->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_ClosedLoop_Recomputed)->Args({16, 30})->Args({16, 150})->Unit(benchmark::kMillisecond)->MinTime(2.0);
