// The committed models against the baselines on their own validation split, as their model cards
// state: the validation demonstrations named in model.bin are regenerated from the synthesiser
// (training set seed 1, as toolchain/nao train makes it), executed on the simulated arm with the
// expert's labels as docs/policy.md defines them, and the runtime's streaming inference is scored
// against the zero action and the repeat-last-action baselines. An autonomous model's rollouts
// start where their demonstrators did (fromOwnStarts), as in training, and it is run closed loop
// from those starts as nao_rt runs it.
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/movement_metrics.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/toolchain_dims.hpp"
#include "replica.hpp"
#include "nao/metrics.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

using namespace nao;

namespace {

constexpr std::uint64_t kTrainingSeed = 1;  // toolchain/nao train: synth --seed 1

// One movement's closed-loop runs from the validation starts, medians (docs/evaluate.md).
struct MovementRuns {
  double dtw_m = 0.0;          ///< hand-path DTW to the nearest validation demonstration
  double still_dtw_m = 0.0;    ///< the same for the arm held at the start
  double demo_nn_dtw_m = 0.0;  ///< the validation demonstrations' own, to the nearest other one
  double speed_ratio = 0.0;    ///< middle-phase RMS hand speed, runs / demonstrations
  double loops_run = 0.0, loops_demo = 0.0;
  /// Run-code models: the medoid replay's DTW to the nearest validation demonstration, and how
  /// far the runs and the replays are from the demonstration their code names.
  double replay_dtw_m = -1.0, code_fidelity_m = -1.0, replay_fidelity_m = -1.0;
};

struct Scores {
  double model = 0.0, zero = 0.0, repeat = 0.0;
  double run_code = -1.0;  ///< with each run's code (models with run codes; -1: none)
  std::size_t samples = 0;
  std::map<std::string, MovementRuns> runs;  ///< autonomous models, by movement
};

// An autonomous model's runs as nao_rt makes them (the evaluator's in-process replay of
// nao_rt --start-pose: the runtime's controller, policy and ODE arm) from every validation
// demonstration's start for its length, scored as nao_toolchain evaluate scores them.
// With run codes, each run's named demonstration (the training demonstration whose code the
// controller picks from its start) is regenerated from the synthesiser with the model's key poses
// and tracked from the run's start by the gain law (the medoid replay, as evaluate makes it).
std::map<std::string, MovementRuns> closedLoop(const ModelFile& model, const ArmModel& arm,
                                               const tools::PolicyData& data, const std::vector<int>& val,
                                               const std::vector<ModelRunCodes>& codes,
                                               const std::map<std::string, std::vector<JointVector>>& centroids) {
  std::map<std::string, MovementRuns> out;
  const SimModel sim = makeSimModel(arm);
  for (std::size_t m = 0; m < model.header.movement_names.size(); ++m) {
    std::vector<const tools::PolicyDemo*> demos;
    std::vector<tools::HandPath> hands;
    for (const int i : val)
      if (data.demos[static_cast<std::size_t>(i)].movement == static_cast<int>(m)) {
        demos.push_back(&data.demos[static_cast<std::size_t>(i)]);
        hands.push_back(tools::handPath(arm, demos.back()->f));
      }
    REQUIRE(demos.size() >= 3);
    const double period_s = demos.front()->t_s[1] - demos.front()->t_s[0];
    // Scored as nao_toolchain evaluate scores its runs.
    const tools::HeldOutScores held = tools::scoreHeldOut(hands, period_s);
    std::vector<double> dtw, still, speed, loops, replay, code_fid, replay_fid;
    for (std::size_t k = 0; k < demos.size(); ++k) {
      const int ticks = static_cast<int>(demos[k]->f.size());
      const JointVector start = clampToLimits(arm, demos[k]->start);
      std::vector<JointVector> q = {start};
      for (const tools::ReplicaTick& t : tools::replayAutonomousRun(model, arm, SimParams{}, static_cast<int>(m), start, ticks))
        q.push_back(t.q);
      const tools::RunScore run = tools::scoreRun(tools::handPath(arm, q), held);
      dtw.push_back(run.nearest.dtw_m);
      still.push_back(tools::nearestDemo(tools::handPath(arm, std::vector<JointVector>(q.size(), start)), hands).dtw_m);
      speed.push_back(run.speed_m_s);
      loops.push_back(run.loops);
      if (codes.empty()) continue;
      const std::string& movement = model.header.movement_names[m];
      const std::string& named = codes[m].names[static_cast<std::size_t>(runCodeIndex(codes[m], start))];
      const std::vector<JointVector> f =
          tools::makeDemoReference(arm, tools::parseMovement(movement), kTrainingSeed,
                                   std::stoi(named.substr(named.rfind('_') + 1)), centroids.at(movement))
              .target;
      const tools::HandPath named_hand = tools::handPath(arm, f);
      const tools::HandPath replay_hand =
          tools::handPath(arm, tools::trackDemo(sim, period_s, servoStepGain(sim.params), f, start, ticks));
      replay.push_back(tools::scoreRun(replay_hand, held).nearest.dtw_m);
      code_fid.push_back(rt::dtwMeanDistance(tools::handPath(arm, q), named_hand));
      replay_fid.push_back(rt::dtwMeanDistance(replay_hand, named_hand));
    }
    MovementRuns r;
    r.dtw_m = tools::median(dtw);
    r.still_dtw_m = tools::median(still);
    r.demo_nn_dtw_m = tools::median(held.nn_dtw_m);
    r.speed_ratio = tools::median(speed) / tools::median(held.speed_m_s);
    r.loops_run = tools::median(loops);
    r.loops_demo = tools::median(held.loops);
    if (!codes.empty()) {
      r.replay_dtw_m = tools::median(replay);
      r.code_fidelity_m = tools::median(code_fid);
      r.replay_fidelity_m = tools::median(replay_fid);
      MESSAGE(model.header.movement_names[m] << ": medoid replay " << r.replay_dtw_m * 1e3 << " mm; code fidelity "
                                             << r.code_fidelity_m * 1e3 << " mm (replay " << r.replay_fidelity_m * 1e3
                                             << " mm)");
    }
    MESSAGE(model.header.movement_names[m] << ": " << demos.size() << " runs, DTW " << r.dtw_m * 1e3 << " mm (held still "
                                           << r.still_dtw_m * 1e3 << " mm, demonstrations' NN "
                                           << r.demo_nn_dtw_m * 1e3 << " mm), speed ratio " << r.speed_ratio << ", loops "
                                           << r.loops_run << " / " << r.loops_demo);
    out[model.header.movement_names[m]] = r;
  }
  return out;
}

template <class Dims>
Scores scoreAs(const std::string& path, const ArmModel& arm, const ModelFile& model) {
  std::vector<const float*> p;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) p.push_back(model.data(i));
  const PolicyWeights<Dims> w =
      bindPolicyWeights<Dims>(p.data(), p.size(), model.header.arch, model.header.conditioning);
  auto ws = makePolicyWorkspace<Dims>();

  const nlohmann::json meta = nlohmann::json::parse(model.header.metadata_json);
  const std::vector<std::string> val = meta.at("split").at("val").get<std::vector<std::string>>();
  REQUIRE(val.size() >= 3);
  Scores s;
  double sum_model = 0.0, sum_zero = 0.0, sum_repeat = 0.0;
  std::map<std::string, std::vector<JointVector>> centroid_map;
  for (std::size_t m = 0; m < model.header.movement_names.size(); ++m)
    for (int k = 0; k < w.clusters; ++k)
      centroid_map[model.header.movement_names[m]].push_back(centroid(w, static_cast<int>(m), k).template cast<double>());
  std::vector<tools::PolicyDemo> demos;
  for (const std::string& name : val) {
    const std::size_t cut = name.rfind('_');
    const std::string movement = name.substr(0, cut);
    const int index = std::stoi(name.substr(cut + 1));
    REQUIRE(centroid_map.count(movement) == 1);
    const std::vector<JointVector>& centroids = centroid_map[movement];
    const tools::ReferenceStream ref =
        tools::makeDemoReference(arm, tools::parseMovement(movement), kTrainingSeed, index, centroids);
    // Labels as nao_toolchain cluster writes them (the key pose in force at each tick).
    tools::PolicyDemo d;
    d.name = name;
    std::vector<double> t_meas;
    std::vector<JointVector> q_meas;
    for (std::size_t t = 0; t < ref.retargeted.size(); ++t) {
      d.t_s.push_back(static_cast<double>(t) / ref.rate_hz);
      d.measured.push_back(ref.measured[t] ? 1 : 0);
      if (!ref.measured[t]) continue;
      t_meas.push_back(d.t_s.back());
      q_meas.push_back(ref.retargeted[t]);
    }
    REQUIRE(!q_meas.empty());
    d.label = tools::keyPoseLabels(centroids, t_meas, q_meas, d.t_s);
    d.f = ref.target;
    d.start = q_meas.front();  // the retargeted pose at the first measured sample (retarget.csv)
    demos.push_back(d);
  }
  // The validation rollouts as training makes them: executed on the simulated arm, clean.
  tools::PolicyData data = tools::makePolicyData(centroid_map, demos);
  // An autonomous model learnt (and was validated) from its demonstrators' own starts: the ones
  // model.bin carries, which nao_rt rolls out from. The files pipeline (smoothed triangulation)
  // gives them; the in-memory one differs at the first sample, so the model's are used.
  if (model.header.conditioning == Conditioning::kAutonomous) {
    const ModelStarts starts = readModelSpec(model.header, RetargetParams{}, path).starts;
    std::size_t found = 0;
    for (tools::PolicyDemo& d : data.demos)
      for (const ModelStart& st : starts[static_cast<std::size_t>(d.movement)])
        if (st.name == d.name) {
          d.start = st.q;
          ++found;
        }
    CHECK(found == val.size());  // every validation demonstration's start travels in model.bin
    data = tools::fromOwnStarts(data);
  }
  std::vector<int> all;
  for (std::size_t i = 0; i < data.demos.size(); ++i)
    if (std::find(val.begin(), val.end(), data.demos[i].name) != val.end()) all.push_back(static_cast<int>(i));
  REQUIRE(all.size() == val.size());
  tools::ExecutionOptions clean;
  clean.noisy_rollouts = 0;
  const std::vector<tools::PolicySequence> seqs =
      tools::executeDemos(data, all, makeSimModel(arm), clean, meta.at("training").at("seed").get<std::uint64_t>());
  // The trainer's validation MSE is of the executed action's first term: this tick's chunk entry
  // plus the law (the action itself for a chunk of 1; the ensemble mixes older chunks in). It is
  // taken at the latent's prior mean (the zero code); a model with run codes is also scored as
  // nao_rt runs it, with the code its controller picks from the demonstration's start.
  const std::vector<ModelRunCodes> codes = readModelSpec(model.header, RetargetParams{}, path).run_codes;
  double sum_coded = 0.0;
  for (const tools::PolicySequence& seq : seqs)
    for (const bool coded : {false, true}) {
      if (coded && codes.empty()) continue;
      setPolicyRunCode(*ws, coded ? runCode(codes, seq.movement, seq.q[0]) : nullptr);
      resetPolicyStream(*ws);
      for (std::size_t t = 0; t < seq.ticks(); ++t) {
        PolicyInput in;
        in.q = seq.q[t].cast<float>();
        in.a_prev = seq.a_prev[t].cast<float>();
        in.r = seq.r[t].cast<float>();
        in.movement = seq.movement;
        in.step = static_cast<int>(std::min<std::size_t>(t, static_cast<std::size_t>(w.max_steps - 1)));
        stepPolicy(w, *ws, in);
        Eigen::Matrix<float, 5, 1> first = ws->chunk.col(0);
        if (w.conditioning == Conditioning::kReference) first += (w.law_gain.array() * in.r.array()).matrix();
        const double e = (first.cast<double>() - seq.a[t]).squaredNorm();
        if (coded) {
          sum_coded += e;
          continue;
        }
        sum_model += e;
        sum_zero += seq.a[t].squaredNorm();
        sum_repeat += (seq.a_prev[t] - seq.a[t]).squaredNorm();
        ++s.samples;
      }
    }
  const double n = static_cast<double>(s.samples * kNumJoints);
  s.model = sum_model / n;
  s.zero = sum_zero / n;
  s.repeat = sum_repeat / n;
  if (!codes.empty()) s.run_code = sum_coded / n;
  if (model.header.conditioning == Conditioning::kAutonomous) s.runs = closedLoop(model, arm, data, all, codes, centroid_map);
  MESSAGE(path << ": " << val.size() << " validation demonstrations, " << s.samples << " samples; MSE rad^2: model "
               << s.model << (codes.empty() ? "" : " (with the runs' codes " + std::to_string(s.run_code) + ")")
               << ", zero action " << s.zero << ", repeat last " << s.repeat);
  // The card's numbers (training pipeline: files, Ceres) are reproduced closely by the
  // in-memory pipeline (no pixel rounding, runtime LM).
  const nlohmann::json& base = meta.at("baselines_rad2").at("val");
  CHECK(s.zero == doctest::Approx(base.at("zero_action").get<double>()).epsilon(0.05));
  CHECK(s.repeat == doctest::Approx(base.at("repeat_last").get<double>()).epsilon(0.05));
  CHECK(s.model == doctest::Approx(meta.at("result").at("val_mse_rad2").get<double>()).epsilon(0.10));
  return s;
}

Scores score(const std::string& path) {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const ModelFile model = readModelFile(path);
  checkJointsMatch(model, arm, path);
  // The committed models are of dimensions the toolchain runs in process (toolchain_dims.hpp).
  return tools::withToolchainDims(model.header.arch, "test_model_quality", [&](auto dims) {
    using Dims = typename decltype(dims)::type;
    checkPolicyArch<Dims>(model.header.arch);
    return scoreAs<Dims>(path, arm, model);
  });
}

std::string modelPath(const char* name) {
  return (std::filesystem::path(NAO_TEST_DATA_DIR).parent_path().parent_path() / "models" / name).string();
}

}  // namespace

TEST_CASE("models/default.bin beats both baselines and reaches at most half the repeat-last-action MSE") {
  const Scores s = score(modelPath("default.bin"));
  CHECK(s.model < s.zero);
  CHECK(s.model < s.repeat);
  CHECK(s.model <= 0.5 * s.repeat);
}

// An autonomous model is judged by its runs, not by one step along a demonstration's trajectory:
// it acts out its own run (the run code of the training demonstrations' medoid nearest the start),
// whose phase is not the held-out demonstration's, so its one-step MSE may well exceed the zero
// action's (models/autonomous.md states both). The card's one-step figures are reproduced
// (score). The bars of docs/evaluate.md that the card shows met on the validation set: on every
// movement the runs come within twice the distance between two validation demonstrations (and
// beat an arm held at its start) and nearer the demonstration their code names than the nearest
// held-out one (they play their code); elbow and whole_arm draw their loops; whole_arm moves at
// its speed and comes within max(1.1 x, + 1 mm) of its medoid replay.
TEST_CASE("models/autonomous.bin's runs from its validation starts make the movement and play their codes") {
  const Scores s = score(modelPath("autonomous.bin"));
  REQUIRE(s.runs.size() == 3);
  for (const auto& [name, r] : s.runs) {
    INFO(name);
    CHECK(r.dtw_m < r.still_dtw_m);
    CHECK(r.dtw_m < 2.0 * r.demo_nn_dtw_m);
    REQUIRE(r.code_fidelity_m >= 0.0);
    CHECK(r.code_fidelity_m < r.dtw_m);
  }
  for (const std::string name : {"elbow", "whole_arm"}) {
    INFO(name);
    CHECK(std::abs(s.runs.at(name).loops_run - s.runs.at(name).loops_demo) <= 1.0);
  }
  const MovementRuns& w = s.runs.at("whole_arm");
  CHECK(w.speed_ratio >= 0.7);
  CHECK(w.speed_ratio <= 1.3);
  CHECK(w.dtw_m <= std::max(1.1 * w.replay_dtw_m, w.replay_dtw_m + 1e-3));
}
