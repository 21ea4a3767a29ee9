// BM_Policy_Libtorch: libtorch eager (the training module, toolchain/src/torch/) on the same
// weights and inputs as BM_Policy_StaticEigen, one input per call, one thread, no autograd.
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
  // Inputs as tensors, prepared before timing.
  struct Args {
    torch::Tensor q, a, r, m, s;
  };
  std::vector<Args> args;
  for (const PolicyInput& in : benchInputs()) {
    Args x;
    x.q = torch::from_blob(const_cast<float*>(in.q.data()), {1, 5}, torch::kFloat).clone();
    x.a = torch::from_blob(const_cast<float*>(in.a_prev.data()), {1, 5}, torch::kFloat).clone();
    x.r = torch::from_blob(const_cast<float*>(in.r.data()), {1, 5}, torch::kFloat).clone();
    x.m = torch::full({1}, in.movement, torch::kLong);
    x.s = torch::full({1}, std::min(in.step, model.header.arch.max_steps - 1), torch::kLong);
    args.push_back(x);
  }
  Percentiles rec;
  std::size_t i = 0;
  for (auto _ : state) {
    const Args& x = args[i++ % args.size()];
    const BenchClock::time_point t0 = BenchClock::now();
    torch::Tensor a = net->act(x.q, x.a, x.r, x.m, x.s);
    benchmark::DoNotOptimize(a.data_ptr<float>());
    const double s = secondsSince(t0);
    state.SetIterationTime(s);
    rec.add(s);
  }
  rec.report(state);
}

}  // namespace

BENCHMARK(BM_Policy_Libtorch)->UseManualTime()->Unit(benchmark::kMicrosecond)->Iterations(1000);
