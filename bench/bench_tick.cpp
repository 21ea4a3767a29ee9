// BM_Tick_Full: the whole controller tick (human kinematics + Algorithm 1 + snap + paper policy
// + limits + 100 x 1 ms ODE steps) on one simulated hour: 36,000 ticks back to back, the held-out
// synthetic whole-arm demonstration (seed 1,000,001) looped as the human reference, with
// the committed models/default.bin. One benchmark iteration = the whole hour; per-stage
// p50/p99/max come from the controller's own stage timings (CLOCK_MONOTONIC), plus peak RSS.
// The label names the policy kernel the weights were bound with (benchPolicyKernel:
// NAO_POLICY_KERNEL=sse forces the SSE one). BM_Tick_Full_Packed: the same hour with the packed fp32 weights (the native
// build's compiled-in default, docs/policy.md "Packed fp32 weights"; the same bits).
#include "bench_policy_common.hpp"
#include "nao/controller.hpp"
#include "nao/model_weights.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/sim_arm.hpp"
#include "nao/quantize.hpp"
#include "nao/robot_loop.hpp"
#include "nao/tools/reference_source.hpp"

#include <sys/resource.h>

#include <string>
#include <utility>

namespace {

using namespace nao;
using namespace nao::bench;

void runTickFull(benchmark::State& state, bool packed) {
  if (!haveModel(state)) return;
  const ModelFile& model = paperModel();
  const ArmModel arm = loadArmModel(NAO_DEFAULT_URDF);
  checkJointsMatch(model, arm, NAO_BENCH_MODEL);
  // Copied into aligned storage the weights own, as nao_rt --weights binds them.
  PolicyWeights<PaperPolicyDims> w = bindPolicyWeights<PaperPolicyDims>(model, benchPolicyKernel());
  AlignedBytes blob;
  if (packed) {
    blob = packModelFp32(model);
    bindPackedWeights<PaperPolicyDims>(w, blob.data.get());
  }
  const int movement = 1;  // whole_arm (sorted movement names)
  std::vector<JointVector> centroids;
  for (int k = 0; k < w.clusters; ++k) centroids.push_back(centroid(w, movement, k).cast<double>());
  const tools::ReferenceStream ref = tools::makeSyntheticReference(arm, tools::Movement::kWholeArm, 1, 0, centroids);
  const ControllerModel<PaperPolicyDims> cm =
      configureController(arm, readModelSpec(model.header, RetargetParams{}, NAO_BENCH_MODEL), std::move(w));
  OdeArmBackend robot(cm.arm, SimParams{}, ref.target.front());
  ControllerData<PaperPolicyDims> data;
  SteadyClock clock;
  constexpr int kTicks = 36000;
  std::vector<double> tick_us(kTicks), retarget_us(kTicks), policy_us(kTicks), sim_us(kTicks);
  for (auto _ : state) {
    activateOnRobot(cm, data, robot, ref.target.front(), movement, clock);
    for (int t = 0; t < kTicks; ++t) {
      const std::size_t i = static_cast<std::size_t>(t) % ref.frames.size();
      const TickRecord& r = runControllerTick(cm, data, robot, ref.present[i] ? &ref.frames[i] : nullptr);
      tick_us[static_cast<std::size_t>(t)] = r.tick_us;
      retarget_us[static_cast<std::size_t>(t)] = r.retarget_us;
      policy_us[static_cast<std::size_t>(t)] = r.policy_us;
      sim_us[static_cast<std::size_t>(t)] = r.sim_us;
    }
    deactivateOnRobot(cm, data, robot);
  }
  auto stats = [&state](const char* name, std::vector<double> v) {
    std::sort(v.begin(), v.end());
    auto at = [&v](double f) { return v[std::min(v.size() - 1, static_cast<std::size_t>(f * static_cast<double>(v.size())))]; };
    state.counters[std::string(name) + "_p50_us"] = at(0.5);
    state.counters[std::string(name) + "_p99_us"] = at(0.99);
    state.counters[std::string(name) + "_max_us"] = v.back();
  };
  stats("tick", tick_us);
  stats("retarget", retarget_us);
  stats("policy", policy_us);
  stats("sim", sim_us);
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  state.counters["rss_MB"] = static_cast<double>(ru.ru_maxrss) / 1024.0;
  state.counters["ticks"] = kTicks;
  state.SetLabel(std::string("policy kernel ") + policyKernelName(cm.policy.kernel) + (packed ? ", packed" : ""));
}

void BM_Tick_Full(benchmark::State& state) { runTickFull(state, false); }
void BM_Tick_Full_Packed(benchmark::State& state) { runTickFull(state, true); }

}  // namespace

BENCHMARK(BM_Tick_Full)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(BM_Tick_Full_Packed)->Unit(benchmark::kSecond)->Iterations(1);
