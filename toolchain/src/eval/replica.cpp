#include "replica.hpp"

#include "nao/controller.hpp"
#include "nao/model_weights.hpp"
#include "nao/robot_loop.hpp"
#include "nao/sim_arm.hpp"
#include "nao/policy.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/toolchain_dims.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>

namespace nao::tools {
namespace {

// Timing plays no part in a replay.
struct ZeroClock final : ControllerClock {
  std::int64_t nowNs() override { return 0; }
};

template <class Dims>
std::vector<ReplicaTick> replay(const ModelFile& model, const ArmModel& arm, const SimParams& sim_params, int movement,
                                const JointVector& start, int ticks) {
  const ControllerModel<Dims> cm =
      configureController(arm, readModelSpec(model.header, RetargetParams{}, "model"), bindPolicyWeights<Dims>(model));
  const PolicyWeights<Dims>& weights = cm.policy;
  OdeArmBackend robot(arm, sim_params, clampToLimits(arm, start));
  ControllerData<Dims> data;
  ZeroClock clock;
  activateOnRobot(cm, data, robot, start, movement, clock);
  std::vector<ReplicaTick> out;
  for (int t = 0; t < ticks; ++t) {
    // The step's inputs as the controller forms them (autonomous mode: r unused).
    PolicyInput in;
    in.q = robot.measured().template cast<float>();
    in.a_prev = data.a_prev.template cast<float>();
    in.movement = movement;
    in.step = static_cast<int>(std::min<std::int64_t>(data.tick, weights.max_steps - 1));
    const TickRecord& rec = runControllerTick(cm, data, robot, nullptr);
    ReplicaTick tick;
    tick.q = rec.q;
    tick.a = rec.a;
    tick.net = data.policy->net_action.template cast<double>();
    for (int j = 0; j < 5; ++j) tick.mass[static_cast<std::size_t>(j)] = data.policy->mass[j];
    const Eigen::Matrix<float, 5, 1> a = data.policy->action;
    for (int j = 0; j < 5; ++j)
      tick.delta[static_cast<std::size_t>(j)] = (ablatedAction(weights, *data.policy, in, 1u << j) - a).template cast<double>().norm();
    out.push_back(tick);
  }
  return out;
}

}  // namespace

bool canReplay(const ModelFile& model) { return hasToolchainDims(model.header.arch); }

std::vector<ReplicaTick> replayAutonomousRun(const ModelFile& model, const ArmModel& arm, const SimParams& sim,
                                             int movement, const JointVector& start, int ticks) {
  return withToolchainDims(model.header.arch, "the replay of a run", [&](auto dims) {
    return replay<typename decltype(dims)::type>(model, arm, sim, movement, start, ticks);
  });
}

void writeAblationCsv(const std::string& path, const std::vector<ReplicaTick>& ticks) {
  std::ofstream csv(path);
  if (!csv) throw UserError("cannot write " + path);
  csv << "tick,mass_0,mass_1,mass_2,mass_3,mass_4,delta_0,delta_1,delta_2,delta_3,delta_4\n";
  char buf[64];
  for (std::size_t t = 0; t < ticks.size(); ++t) {
    csv << t;
    for (float m : ticks[t].mass) {
      std::snprintf(buf, sizeof buf, ",%.9g", static_cast<double>(m));
      csv << buf;
    }
    for (double d : ticks[t].delta) {
      std::snprintf(buf, sizeof buf, ",%.9g", d);
      csv << buf;
    }
    csv << '\n';
  }
  if (!csv) throw UserError("cannot write " + path);
}

}  // namespace nao::tools
