// BM_Policy_Libtorch: libtorch eager (the training module, toolchain/src/torch/) on the same
// weights and inputs as BM_Policy_StaticEigen, one tick per call (a forward over the whole
// window: libtorch has no key/value cache here), one thread, no autograd.
#include "bench_policy_common.hpp"
#include "policy_torch.hpp"

#include <torch/torch.h>

namespace {

using namespace nao;
using namespace nao::bench;

void BM_Policy_Libtorch(benchmark::State& state) {
  if (!haveModel(state)) return;
  torch::set_num_threads(1);
  torch::NoGradGuard no_grad;
  const ModelFile& model = paperModel();
  tools::PolicyNet net(model.header.arch, model.header.conditioning);
  const auto tensors = tools::manifestTensors(net);
  for (std::size_t i = 0; i < tensors.size(); ++i) {
    torch::Tensor dst = tensors[i].second;
    dst.view({-1}).copy_(torch::from_blob(const_cast<float*>(model.data(i)),
                                          {static_cast<long>(model.tensors[i].spec.count())}, torch::kFloat));
  }
  net->eval();
  // Without a key/value cache, one tick's action is a forward over the whole window: W ticks of
  // inputs [1,W,5] ending at each bench input (prepared before timing); the action is the last tick's.
  const int window = model.header.arch.window;
  struct Args {
    torch::Tensor q, a, r, m;
  };
  std::vector<Args> args;
  const std::vector<PolicyInput>& inputs = benchInputs();
  for (std::size_t k = 0; k < inputs.size(); ++k) {
    Args x;
    x.q = torch::empty({1, window, 5});
    x.a = torch::empty({1, window, 5});
    x.r = torch::empty({1, window, 5});
    for (int t = 0; t < window; ++t) {
      const PolicyInput& in = inputs[(k + inputs.size() * 4 - static_cast<std::size_t>(window - 1 - t)) % inputs.size()];
      for (int j = 0; j < 5; ++j) {
        x.q[0][t][j] = in.q[j];
        x.a[0][t][j] = in.a_prev[j];
        x.r[0][t][j] = in.r[j];
      }
    }
    x.m = torch::full({1}, inputs[k].movement, torch::kLong);
    args.push_back(x);
  }
  Percentiles rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const Args& x = args[i++ % args.size()];
    const BenchClock::time_point t0 = BenchClock::now();
    torch::Tensor a = net->act(x.q, x.a, x.r, x.m).select(1, window - 1);
    benchmark::DoNotOptimize(a.data_ptr<float>());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(s);
  }
  rec.report(state);
}

}  // namespace

BENCHMARK(BM_Policy_Libtorch)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(1000);

namespace {

// BM_TrainStep_Paper/T: one training sequence of T ticks through the paper net, forward and
// backward (the unit of work a rank does per global batch), one thread, random weights and inputs.
void BM_TrainStep_Paper(benchmark::State& state) {
  torch::set_num_threads(1);
  torch::manual_seed(1);
  nao::tools::PolicyNet net(nao::paperArch(), nao::Conditioning::kAutonomous);
  net->train();
  const std::int64_t ticks = state.range(0);
  nao::tools::PolicyBatch b;
  b.qn = torch::randn({1, ticks, 5});
  b.an = torch::randn({1, ticks, 5});
  b.rn = torch::zeros({1, ticks, 5});
  b.movement = torch::zeros({1}, torch::kInt64);
  const torch::Tensor target = torch::randn({1, ticks, 5, 1});
  for (auto _ : state) {
    for (auto& p : net->parameters()) p.mutable_grad() = torch::Tensor();
    const torch::Tensor loss = (net->forward(b).chunk - target).square().mean();
    loss.backward();
    benchmark::DoNotOptimize(loss.data_ptr<float>());
  }
  // Seconds per tick: constant if the cost is linear in the length.
  state.counters["s_per_tick"] = benchmark::Counter(static_cast<double>(ticks), benchmark::Counter::kIsIterationInvariantRate |
                                                                                    benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK(BM_TrainStep_Paper)->Arg(50)->Arg(100)->Arg(150)->Arg(188)->Unit(benchmark::kMillisecond)->MinTime(2.0);
