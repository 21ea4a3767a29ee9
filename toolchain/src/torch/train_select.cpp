#include "train_select.hpp"

#include "nao/controller.hpp"
#include "nao/policy.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/toolchain_dims.hpp"
#include "policy_train.hpp"
#include "nao/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

namespace nao::tools {
namespace {

// The net under training as the runtime runs it: its manifest floats, the weights bound over them
// (views: the floats live as long as this) and a policy workspace. step() is nao_rt's policy step.
template <class Dims>
struct RuntimeNet {
  explicit RuntimeNet(const PolicyNet& net)
      : floats(manifestFloats(net)), weights(bind(floats, net)), ws(makePolicyWorkspace<Dims>()) {}
  RuntimeNet(const RuntimeNet&) = delete;
  RuntimeNet& operator=(const RuntimeNet&) = delete;

  /// Starts a run (t = 0) with `code` (nullptr: none), as the controller does at activate.
  void start(const float* code) {
    resetPolicyStream(*ws);
    setPolicyRunCode(*ws, code);
  }
  JointVector step(int movement, int t, const JointVector& q, const JointVector& a_prev, const JointVector& r) {
    PolicyInput in;
    in.q = q.cast<float>();
    in.a_prev = a_prev.cast<float>();
    in.r = r.cast<float>();  // ignored in autonomous mode
    in.movement = movement;
    in.step = t;
    return stepPolicy(weights, *ws, in).template cast<double>();
  }

  std::vector<std::vector<float>> floats;
  PolicyWeights<Dims> weights;
  std::unique_ptr<PolicyWorkspace<Dims>> ws;

 private:
  static PolicyWeights<Dims> bind(const std::vector<std::vector<float>>& floats, const PolicyNet& net) {
    std::vector<const float*> pointers;
    for (const std::vector<float>& f : floats) pointers.push_back(f.data());
    return bindPolicyWeights<Dims>(pointers.data(), pointers.size(), net->arch(), net->conditioning());
  }
};

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

template <class Dims>
std::vector<PolicyRun> runsWith(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                                const PolicyNet& net, const std::vector<ModelRunCodes>* codes) {
  RuntimeNet<Dims> rt(net);
  const RolloutPolicy policy = [&](int movement, int t, const JointVector& q, const JointVector& a_prev,
                                   const JointVector& r) -> JointVector {
    // The run's code, as the controller chooses it at activate.
    if (t == 0) rt.start(codes != nullptr ? runCode(*codes, movement, q) : nullptr);
    return rt.step(movement, t, q, a_prev, r);
  };
  // An autonomous model's runs keep to its workspace envelope, as nao_rt's controller does.
  std::vector<JointEnvelope> workspace;
  if (net->conditioning() == Conditioning::kAutonomous && ControllerParams{}.workspace_margin_rad >= 0.0)
    workspace = workspaceEnvelopes(rt.weights, ControllerParams{}.workspace_margin_rad, demonstratedWorkspace(data));
  return rolloutPolicy(data, demos, sim, policy, workspace.empty() ? nullptr : &workspace);
}

}  // namespace

bool hasRuntimeStep(const PolicyArch& arch) {
  return arch.chunk <= kPolicyMaxChunk && hasToolchainDims(arch);
}

std::vector<PolicyRun> netRuns(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                               const PolicyNet& net, const std::vector<ModelRunCodes>* codes) {
  if (net->arch().chunk > kPolicyMaxChunk)
    throw UserError("rollouts through the runtime's step: the chunk exceeds what the runtime holds");
  return withToolchainDims(net->arch(), "rollouts through the runtime's step", [&](auto dims) {
    return runsWith<typename decltype(dims)::type>(data, demos, sim, net, codes);
  });
}

SelectionReference selectionReference(const PolicyData& data, const std::vector<int>& val, const ArmModel& arm,
                                      double period_s, const std::vector<ModelRunCodes>* codes) {
  const auto nm = static_cast<std::size_t>(data.movements());
  SelectionReference ref;
  ref.demos.resize(nm);
  ref.q_min.assign(nm, JointVector::Constant(std::numeric_limits<double>::infinity()));
  ref.q_max.assign(nm, JointVector::Constant(-std::numeric_limits<double>::infinity()));
  for (int d : val) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    ref.demos[static_cast<std::size_t>(demo.movement)].push_back(handPath(arm, demo.f));
  }
  // The demonstrated joint range: the trajectories and the starts they begin at.
  const std::vector<ModelWorkspace> range = demonstratedWorkspace(data);
  for (std::size_t m = 0; m < range.size() && m < nm; ++m) {
    ref.q_min[m] = range[m].lo;
    ref.q_max[m] = range[m].hi;
  }
  for (std::size_t m = 0; m < nm; ++m) {
    const std::vector<HandPath>& paths = ref.demos[m];
    std::vector<double> speed, loops, nn;
    Eigen::Matrix<double, 3, 2> plane = Eigen::Matrix<double, 3, 2>::Identity();
    if (!paths.empty()) plane = loopPlane(paths);
    for (std::size_t i = 0; i < paths.size(); ++i) {
      speed.push_back(middleRmsSpeed(paths[i], period_s));
      loops.push_back(loopCount(paths[i], plane));
      const NearestDemo n = nearestDemo(paths[i], paths, static_cast<int>(i));
      if (n.index >= 0) nn.push_back(n.dtw_m);
    }
    ref.plane.push_back(plane);
    ref.demo_speed.push_back(median(speed));
    ref.demo_loops.push_back(median(loops));
    ref.nn_dtw_m.push_back(median(nn));
  }
  if (codes != nullptr)
    for (const ModelRunCodes& c : *codes) {
      ref.code_paths.emplace_back();
      for (const std::string& name : c.names) {
        const auto it = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& d) { return d.name == name; });
        if (it == data.demos.end()) throw std::logic_error("selection: no demonstration '" + name + "' for its run code");
        ref.code_paths.back().push_back(handPath(arm, it->f));
      }
    }
  return ref;
}

void addReplaySpeeds(SelectionReference& ref, const PolicyData& data, const std::vector<int>& val, const SimModel& sim,
                     double period_s, const std::vector<ModelRunCodes>& codes) {
  ref.replay_speed.assign(data.demos.size(), kNaN);
  for (int d : val) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    const ModelRunCodes& c = codes.at(static_cast<std::size_t>(demo.movement));
    // The run starts where its demonstrator did and lasts its f's ticks (rolloutPolicy).
    const JointVector start = clampToLimits(sim.arm, demo.start);
    const int code = runCodeIndex(c, start);
    if (code < 0) continue;
    const std::string& name = c.names[static_cast<std::size_t>(code)];
    const auto it = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& x) { return x.name == name; });
    if (it == data.demos.end()) throw std::logic_error("selection: no demonstration '" + name + "' for its run code");
    const std::vector<JointVector> q =
        trackDemo(sim, period_s, servoStepGain(sim.params), it->f, start, static_cast<int>(demo.f.size()) - 1);
    ref.replay_speed[static_cast<std::size_t>(d)] = middleRmsSpeed(handPath(sim.arm, q), period_s);
  }
}

void scoreRuns(const std::vector<PolicyRun>& runs, const SelectionReference& ref, const ArmModel& arm, double period_s,
               EpochStats& st, const std::vector<ModelRunCodes>* codes) {
  const std::size_t nm = ref.demos.size();
  const bool fidelity = codes != nullptr && ref.code_paths.size() == nm;
  std::vector<std::vector<double>> dtw(nm), speed(nm), loops(nm), played(nm), vs_replay(nm);
  std::vector<double> excess(nm, 0.0);
  std::vector<bool> broken(nm, false);
  for (const PolicyRun& run : runs) {
    const auto m = static_cast<std::size_t>(run.movement);
    bool finite = true;
    for (const JointVector& q : run.q) finite = finite && q.allFinite();
    if (!finite || ref.demos[m].empty()) {
      broken[m] = true;
      continue;
    }
    const HandPath path = handPath(arm, run.q);
    dtw[m].push_back(nearestDemo(path, ref.demos[m]).dtw_m);
    speed[m].push_back(middleRmsSpeed(path, period_s));
    if (!ref.replay_speed.empty()) vs_replay[m].push_back(speed[m].back() / ref.replay_speed.at(static_cast<std::size_t>(run.demo)));
    loops[m].push_back(loopCount(path, ref.plane[m]));
    for (const JointVector& q : run.q)
      excess[m] = std::max({excess[m], (q - ref.q_max[m]).maxCoeff(), (ref.q_min[m] - q).maxCoeff()});
    const int code = fidelity ? runCodeIndex((*codes)[m], run.q.front()) : -1;
    if (code >= 0) played[m].push_back(rt::dtwMeanDistance(path, ref.code_paths[m][static_cast<std::size_t>(code)]));
  }
  st.rollouts.assign(nm, MovementScore{});
  double sum = 0.0, sum_played = 0.0;
  int n = 0;
  st.makes_movement = true;
  st.movements_made = 0;
  for (std::size_t m = 0; m < nm; ++m) {
    if (dtw[m].empty() && !broken[m]) continue;  // no validation run of this movement
    MovementScore& s = st.rollouts[m];
    s.dtw_m = broken[m] ? kNaN : median(dtw[m]);
    s.speed_ratio = broken[m] ? kNaN : median(speed[m]) / ref.demo_speed[m];
    s.loops_run = broken[m] ? kNaN : median(loops[m]);
    s.loops_demo = ref.demo_loops[m];
    s.range_excess_rad = broken[m] ? kNaN : excess[m];
    s.code_fidelity_m = broken[m] || played[m].empty() ? kNaN : median(played[m]);
    s.speed_vs_replay = broken[m] || vs_replay[m].empty() ? kNaN : median(vs_replay[m]);
    // The speed a run is held to: the held-out demonstrations', or with replay speeds what it plays.
    const double pace = ref.replay_speed.empty() ? s.speed_ratio : s.speed_vs_replay;
    // Speed and loops alone are met by a run that is nowhere near the demonstrations (an early
    // epoch's wrist at 4x their nearest-neighbour DTW): it must also come within twice that
    // (unknown with a single validation demonstration: then not asked).
    const bool made = pace >= 0.7 && pace <= 1.3 && std::abs(s.loops_run - s.loops_demo) <= 1.0 &&
                      s.range_excess_rad <= 0.1 && (!std::isfinite(ref.nn_dtw_m[m]) || s.dtw_m < 2.0 * ref.nn_dtw_m[m]);
    st.makes_movement = st.makes_movement && made;
    st.movements_made += made ? 1 : 0;
    sum += s.dtw_m;
    sum_played += s.code_fidelity_m;
    ++n;
  }
  st.rollout_dtw_m = n > 0 ? sum / n : kNaN;
  st.code_fidelity_m = n > 0 && fidelity ? sum_played / n : kNaN;
}

bool betterEpoch(const EpochStats& a, const EpochStats& b, bool by_fidelity) {
  if (by_fidelity) {
    const auto inRange = [](const EpochStats& e) {
      bool ok = true;
      for (const MovementScore& s : e.rollouts) ok = ok && s.range_excess_rad <= 0.1;
      return ok;
    };
    if (!std::isfinite(a.code_fidelity_m)) return false;
    if (!std::isfinite(b.code_fidelity_m)) return true;
    if (inRange(a) != inRange(b)) return inRange(a);
    return a.code_fidelity_m < b.code_fidelity_m;
  }
  if (!std::isfinite(a.rollout_dtw_m)) return false;
  if (!std::isfinite(b.rollout_dtw_m)) return true;
  if (a.makes_movement != b.makes_movement) return a.makes_movement;
  // Short of every movement, the epoch that makes more of them: the lowest DTW alone favours
  // runs that average the cycles away.
  if (a.movements_made != b.movements_made) return a.movements_made > b.movements_made;
  return a.rollout_dtw_m < b.rollout_dtw_m;
}

}  // namespace nao::tools
