// nao_toolchain evaluate: whether an autonomous model makes its movements, into OUT/summary.json
// (docs/evaluate.md). Per movement, nao_rt's runs of the model from every held-out
// demonstration's start are scored against the held-out demonstrations (hand-path DTW to the
// nearest, middle-phase speed, loops, joint range, distinct runs), against the best fixed
// trajectory the data give (the medoid replay) and the linear AR baseline; the network's share of
// the action and the attention ablation come from an in-process replay of each run through the
// runtime's own controller. With a reference model, the reference mode's hand RMSE on recorded
// references (nao_rt runs) beside the blend law and the gain law (nao_rt's run in process, the
// laws in place of the policy).
#include "jobs.hpp"
#include "replica.hpp"

#include "nao/controller.hpp"
#include "nao/csv_reader.hpp"
#include "nao/skeleton_csv.hpp"
#include "nao/tools/baseline_laws.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/toolchain_dims.hpp"
#include "nao/metrics.hpp"
#include "rt_run.hpp"

#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

struct Args {
  std::string model = "models/autonomous.bin";
  std::string reference_model = "models/default.bin";
  std::string data = "out/train/data";
  std::string recordings;
  std::string out = "out/eval";
  std::string urdf = NAO_DEFAULT_URDF;
  std::string nao_rt, reference_nao_rt;
  std::string movement = "all";
  std::vector<std::uint64_t> seeds = {1, 2, 3, 4, 5};
  int jobs = 2;
  int max_order = 12;
  int min_demos = 0;  ///< 0: 16 for a synthetic validation set, 4 otherwise
  std::int64_t test_seed = -1;
  int test_demos = 16;
  RecordingInput input;
  bool no_reference = false;
};

std::string exactNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

json numberOrNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

std::string millimetres(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", m * 1e3);
  return buf;
}

// The names of `movement`'s demonstrations ("<movement>_<digits>") among a split's.
std::vector<std::string> splitNames(const std::vector<std::string>& split, const std::string& movement) {
  std::vector<std::string> names;
  for (const std::string& n : split)
    if (n.rfind(movement + "_", 0) == 0 && n.find_first_not_of("0123456789", movement.size() + 1) == std::string::npos)
      names.push_back(n);
  return names;
}

// A nao_rt run's joint and hand paths: the start pose (at rest, clamped), then every tick's
// (ticks.csv q_*, ee_*: exact doubles).
struct RunPaths {
  std::vector<JointVector> q;
  HandPath hand;
};
RunPaths readRun(const ArmModel& arm, const JointVector& start, const fs::path& ticks_csv) {
  RunPaths r;
  r.q.push_back(clampToLimits(arm, start));
  r.hand = handPath(arm, r.q);
  CsvReader csv(ticks_csv.string(), "ticks.csv");
  std::size_t cq[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j) cq[j] = csv.column("q_" + std::to_string(j));
  const std::size_t x = csv.column("ee_x"), y = csv.column("ee_y"), z = csv.column("ee_z");
  while (csv.next()) {
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j) q[j] = csv.number(cq[j]);
    r.q.push_back(q);
    r.hand.emplace_back(csv.number(x), csv.number(y), csv.number(z));
  }
  return r;
}

// The worst excursion of q beyond [lo, hi] over a trajectory, rad (0 inside).
double rangeExcess(const std::vector<JointVector>& q, const JointVector& lo, const JointVector& hi) {
  double worst = 0.0;
  for (const JointVector& x : q) worst = std::max({worst, (x - hi).maxCoeff(), (lo - x).maxCoeff()});
  return worst;
}

json arJson(const LinearArModel& m) {
  json joints = json::array();
  for (const LinearArJoint& j : m.joints)
    joints.push_back({{"order", j.order}, {"c", j.c}, {"beta", j.beta}, {"alpha", j.alpha}});
  return joints;
}

// What one movement's evaluation holds.
struct MovementWork {
  std::string name;
  int index = 0;              ///< in the model's movement names
  std::string set_kind;       ///< validation, test or recordings
  DemoSet held, train;
  std::vector<int> start_index;  ///< per held-out demonstration: --start I, or -1 (--start-pose)
  std::vector<std::size_t> auto_jobs, ref_jobs;  ///< nao_rt's runs of the model; of the reference model, per seed
  std::vector<fs::path> references;              ///< per seed: the recorded reference (skeleton CSV)
  std::vector<double> law_rmse, gain_rmse;       ///< per seed: the baselines' hand RMSE (in process)
};

// The synthesiser's test set of `movement`: demonstrations 0..n-1 of run seed 1000000 + S written
// as recordings into `dir`, then processed as any recording is.
DemoSet syntheticTestSet(const ArmModel& arm, const std::string& movement, std::uint64_t test_seed, int n,
                         const fs::path& dir, const RecordingInput& input, const RetargetParams& retarget,
                         const std::vector<JointVector>& key_poses) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw UserError("cannot create " + dir.string() + ": " + ec.message());
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) {
    const SynthDemo demo = generateDemo(parseMovement(movement), i, kReferenceSeedBase + test_seed, false);
    writeDemo(demo, dir.string());
    names.push_back(demo.name);
  }
  return demoSetFromRecordings(arm, dir.string(), names, input, retarget, key_poses, movement + " test set");
}

// Everything an evaluation reads and decides before it runs anything.
struct Setup {
  ArmModel arm;
  ModelFile model;
  ModelSpec spec;       ///< the model's starts, retargeting setting, split and data fingerprint
  fs::path nao_rt, reference_nao_rt, out;
  bool recordings = false, test = false, reference = false;
  int min_demos = 0;
  std::unique_ptr<PolicyData> data;  ///< the synthetic data set (not with --recordings)
  PolicyArch reference_arch;         ///< the reference model's (its baselines run in process)
  SimParams sim_params;
  double period_s = ControllerParams{}.period_s;
  double gain = 0.0;                 ///< the gain law's and the replays' g (servoStepGain)
};

// The data set of the model's synthetic demonstrations, checked against its fingerprint.
std::unique_ptr<PolicyData> readDataSet(const Args& a, const ModelSpec& spec) {
  std::error_code ec;
  if (!fs::is_directory(a.data, ec))
    throw UserError(a.data + ": no data set (toolchain/nao train data makes it; the baselines are fitted on the model's training demonstrations)");
  std::fprintf(stderr, "evaluate: reading the data set %s\n", a.data.c_str());
  auto data = std::make_unique<PolicyData>(loadPolicyData(a.data));
  const std::string have = hex64(dataFingerprint(*data));
  const std::string want = !spec.data_fingerprint.empty() ? spec.data_fingerprint : std::string("an unrecorded one");
  if (have != want)
    throw UserError(a.data + " has data fingerprint " + have + ", " + a.model + " was trained on " + want +
                    " (toolchain/nao train data rebuilds the data set)");
  return data;
}

Setup setUp(const Args& a) {
  if (a.seeds.empty()) throw UserError("--seeds needs at least one seed");
  Setup s;
  s.arm = loadArmModel(a.urdf);
  // The model's runs and the reference model's may need two nao_rt builds (one per architecture).
  const fs::path beside = fs::read_symlink("/proc/self/exe").parent_path() / "nao_rt";
  s.nao_rt = a.nao_rt.empty() ? beside : fs::path(a.nao_rt);
  s.reference_nao_rt = a.reference_nao_rt.empty() ? beside : fs::path(a.reference_nao_rt);
  s.model = readModelFile(a.model);
  checkJointsMatch(s.model, s.arm, a.model);
  if (s.model.header.conditioning != Conditioning::kAutonomous)
    throw UserError(a.model + " is not an autonomous-mode model (--model)");
  s.spec = readModelSpec(s.model.header, RetargetParams{}, a.model);
  s.recordings = !a.recordings.empty();
  s.test = a.test_seed >= 0;
  if (s.recordings && s.test) throw UserError("--test-seed scores a synthetic test set; --recordings scores the model's held-out recordings: take one");
  s.reference = !s.recordings && !a.no_reference;
  // The reference model's nao_rt is needed only where it runs.
  std::vector<std::pair<fs::path, const char*>> exes{{s.nao_rt, "--nao-rt"}};
  if (s.reference) exes.emplace_back(s.reference_nao_rt, "--reference-nao-rt");
  for (const auto& [exe, option] : exes)
    if (access(exe.c_str(), X_OK) != 0)
      throw UserError("nao_rt not found at " + exe.string() + ": build it (toolchain/nao build) or pass " + option +
                      " PATH");
  if (s.reference) s.reference_arch = readModelFile(a.reference_model).header.arch;
  s.min_demos = a.min_demos > 0 ? a.min_demos : (!s.recordings && !s.test ? 16 : 4);
  if (!s.recordings) s.data = readDataSet(a, s.spec);
  s.out = a.out;
  std::error_code ec;
  fs::create_directories(s.out, ec);
  if (ec) throw UserError("cannot create " + a.out + ": " + ec.message());
  s.gain = servoStepGain(s.sim_params);
  return s;
}

// One movement's held-out and training demonstrations, and its nao_rt runs into `jobs`: the
// model's from every held-out start, the reference model's on every seed's recorded reference.
MovementWork planMovement(const Args& a, const Setup& s, std::size_t mi, std::vector<Job>& jobs) {
  const std::string& name = s.model.header.movement_names[mi];
  MovementWork w;
  w.name = name;
  w.index = static_cast<int>(mi);
  const std::vector<JointVector> key_poses = modelKeyPoses(s.model, w.index);
  const std::vector<std::string> val_names = splitNames(s.spec.split.val, name),
                                 train_names = splitNames(s.spec.split.train, name);
  if (s.recordings) {
    w.set_kind = "recordings";
    w.held = demoSetFromRecordings(s.arm, a.recordings, val_names, a.input, s.spec.retarget, key_poses, name + " held out");
    w.train = demoSetFromRecordings(s.arm, a.recordings, train_names, a.input, s.spec.retarget, key_poses, name + " training");
  } else {
    w.train = demoSetFrom(s.arm, *s.data, name, train_names);
    if (s.test) {
      w.set_kind = "test";
      w.held = syntheticTestSet(s.arm, name, static_cast<std::uint64_t>(a.test_seed), a.test_demos,
                                s.out / "test_recordings" / name, a.input, s.spec.retarget, key_poses);
    } else {
      w.set_kind = "validation";
      w.held = demoSetFrom(s.arm, *s.data, name, val_names);
    }
  }
  if (static_cast<int>(w.held.size()) < s.min_demos)
    throw UserError(a.model + ": " + std::to_string(w.held.size()) + " held-out demonstration(s) of " + name +
                    "; this evaluation needs at least " + std::to_string(s.min_demos) + " (--min-demos)");
  if (w.train.size() == 0) throw UserError(a.model + ": no training demonstration of " + name + " (split.train)");
  // A validation demonstration is one of the model's starts: nao_rt runs it with --start I.
  for (const std::string& n : w.held.names) {
    int index = -1;
    if (w.set_kind != "test")
      for (std::size_t i = 0; i < s.spec.starts[mi].size(); ++i)
        if (s.spec.starts[mi][i].name == n) index = static_cast<int>(i);
    w.start_index.push_back(index);
  }

  const fs::path mdir = s.out / name;
  std::error_code ec;
  for (const char* sub : {"autonomous", "reference", "blend_law", "gain_law", "references", "demos"})
    fs::remove_all(mdir / sub, ec);
  fs::create_directories(mdir / "demos", ec);
  for (std::size_t i = 0; i < w.held.size(); ++i) {
    writeTrajectoryCsv((mdir / "demos" / (w.held.names[i] + ".csv")).string(), w.held.f[i], s.period_s);
    std::vector<std::string> argv = {s.nao_rt.string(), "--weights", a.model, "--urdf", a.urdf,
                                     "--reference", "none", "--movement", name};
    if (w.start_index[i] >= 0) {
      argv.insert(argv.end(), {"--start", std::to_string(w.start_index[i])});
    } else {
      std::string pose;
      for (int j = 0; j < kNumJoints; ++j) pose += (j > 0 ? "," : "") + exactNumber(w.held.start[i][j]);
      argv.insert(argv.end(), {"--start-pose", pose});
    }
    argv.insert(argv.end(), {"--ticks", std::to_string(w.held.f[i].size()), "--zero-timing", "--log",
                             (mdir / "autonomous" / w.held.names[i]).string()});
    w.auto_jobs.push_back(jobs.size());
    jobs.push_back({name + " autonomous " + w.held.names[i], argv, mdir / "autonomous" / w.held.names[i]});
  }
  if (!s.reference) return w;
  for (std::uint64_t seed_number : a.seeds) {
    const std::string seed = std::to_string(seed_number);
    // The reference: demonstration 0 of run seed 1000000 + s (never a training seed) as the two
    // cameras and the triangulation see it, written exactly (17 digits).
    const fs::path skeleton = mdir / "references" / ("seed_" + seed + ".csv");
    fs::create_directories(skeleton.parent_path(), ec);
    writeSkeletonCsv(skeleton.string(),
                     observeDemo(generateDemo(parseMovement(name), 0, kReferenceSeedBase + seed_number, false)), false, 17);
    w.references.push_back(skeleton);
    const fs::path dir = mdir / "reference" / ("seed_" + seed);
    w.ref_jobs.push_back(jobs.size());
    jobs.push_back({name + " reference seed " + seed,
                    {s.reference_nao_rt.string(), "--weights", a.reference_model, "--urdf", a.urdf, "--reference",
                     "file:" + skeleton.string(), "--movement", name, "--zero-timing", "--log", dir.string()},
                    dir});
  }
  return w;
}

// The hand RMSE of nao_rt's run of the reference model on a recorded reference with `law` in
// place of the policy: the runtime's own run in process (rt::runController), its run directory
// in `dir` and its printed output in dir/run.log.
double baselineRmse(const Args& a, const Setup& s, const MovementWork& w, std::size_t k, nao::ActionLaw& law,
                    const fs::path& dir) {
  rt::RunOptions o;
  o.weights_path = a.reference_model;
  o.urdf_path = a.urdf;
  o.reference = "file:" + w.references[k].string();
  o.movement = w.name;
  o.zero_timing = true;
  o.log_dir = dir.string();
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::ofstream log(dir / "run.log");
  const rt::RunReport r = withToolchainDims(s.reference_arch, "the baselines of the reference model", [&](auto dims) {
    return rt::runController<typename decltype(dims)::type>(o, log, log, nullptr, &law);
  });
  if (r.status != 0) throw UserError(w.name + " " + law.name() + " seed " + std::to_string(a.seeds[k]) + ": " + r.error);
  if (!std::isfinite(r.ee_rmse_m)) throw UserError((dir / "summary.json").string() + ": no number 'ee_rmse_m'");
  return r.ee_rmse_m;
}

// The blend law and the gain law on every movement's recorded references, in process.
void runBaselines(const Args& a, const Setup& s, std::vector<MovementWork>& work) {
  for (MovementWork& w : work)
    for (std::size_t k = 0; k < w.references.size(); ++k) {
      const std::string seed = "seed_" + std::to_string(a.seeds[k]);
      BlendLaw blend(kFeatureBlendPole);
      GainLaw gain(s.gain);
      w.law_rmse.push_back(baselineRmse(a, s, w, k, blend, s.out / w.name / "blend_law" / seed));
      w.gain_rmse.push_back(baselineRmse(a, s, w, k, gain, s.out / w.name / "gain_law" / seed));
      std::fprintf(stderr, "evaluate: %s blend and gain law seed %llu (in process)\n", w.name.c_str(),
                   static_cast<unsigned long long>(a.seeds[k]));
    }
}

// The scores of a movement's autonomous runs, one entry per run (detail.json "runs").
struct AutonomousScores {
  std::vector<double> auto_dtw, medoid_dtw, neighbour_dtw, ar_dtw, speed, loops, share, excess;
  std::vector<double> code_fidelity, replay_fidelity, replay_speed, replay_loops;
  std::vector<double> speed_vs_replay;  ///< per run: its middle-phase speed over its medoid replay's
  std::vector<HandPath> run_hands, replay_hands;
  std::size_t distinct = 0, replay_distinct = 0;  ///< distinctRuns of the runs' and the replays' hand paths
  json runs = json::array();
  std::size_t replay_mismatch = 0;
};

// The demonstrations' joint range (held out and training: their trajectories and the starts they
// begin at), as [lo, hi].
std::pair<JointVector, JointVector> demonstratedRange(const MovementWork& w) {
  JointVector lo = JointVector::Constant(1e9), hi = JointVector::Constant(-1e9);
  for (const DemoSet* d : {&w.held, &w.train}) {
    for (const auto& f : d->f)
      for (const JointVector& q : f) {
        lo = lo.cwiseMin(q);
        hi = hi.cwiseMax(q);
      }
    for (const JointVector& q : d->start) {
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
  }
  return {lo, hi};
}

// Every autonomous run of the movement scored: against the held-out demonstrations, beside the
// medoid and neighbour replays and the linear AR baseline from its start; with the replay, the
// network's share and the attention ablation (ablation.csv).
AutonomousScores scoreAutonomousRuns(const Setup& s, const SimModel& sim, const MovementWork& w,
                                     const std::vector<Job>& jobs, const HeldOutScores& held, const LinearArModel& ar) {
  const auto [lo, hi] = demonstratedRange(w);
  const bool replay = canReplay(s.model);
  SimData sim_data(sim, w.held.start.front());
  AutonomousScores r;
  for (std::size_t i = 0; i < w.held.size(); ++i) {
    const Job& job = jobs[w.auto_jobs[i]];
    const json summary = readSummary(job);
    const int ticks = static_cast<int>(w.held.f[i].size());
    if (!summary.contains("ticks") || summary["ticks"] != ticks)
      throw UserError((job.dir / "summary.json").string() + ": not the run of " + w.held.names[i]);
    const RunPaths run = readRun(s.arm, w.held.start[i], job.dir / "ticks.csv");
    const RunScore score = scoreRun(run.hand, held);
    const NearestDemo& near = score.nearest;
    r.auto_dtw.push_back(near.dtw_m);
    r.speed.push_back(score.speed_m_s);
    r.loops.push_back(score.loops);
    r.excess.push_back(rangeExcess(run.q, lo, hi));
    r.run_hands.push_back(run.hand);
    const NeighbourReplays rep5 = neighbourReplays(sim, s.period_s, s.gain, w.train, w.held.start[i], ticks);
    std::vector<double> each;  // in rep5.demos' order, the medoid among them
    for (const std::vector<JointVector>& q : rep5.q) each.push_back(nearestDemo(handPath(s.arm, q), w.held.hand).dtw_m);
    r.medoid_dtw.push_back(each[rep5.medoidSlot()]);
    r.neighbour_dtw.push_back(median(each));
    // What the run plays: the named demonstration (the medoid, whose code a run-code model's
    // run takes), and how far the run and the medoid replay are from it.
    const HandPath& named = w.train.hand[static_cast<std::size_t>(rep5.medoid)];
    r.replay_hands.push_back(handPath(s.arm, rep5.medoidQ()));
    r.code_fidelity.push_back(rt::dtwMeanDistance(run.hand, named));
    r.replay_fidelity.push_back(rt::dtwMeanDistance(r.replay_hands.back(), named));
    // Beside the run, for its hand-path figure (toolchain/nao analyze): the demonstration it plays.
    writeTrajectoryCsv((job.dir / "named_demo.csv").string(), w.train.f[static_cast<std::size_t>(rep5.medoid)],
                       s.period_s);
    const RunScore replay_score = scoreRun(r.replay_hands.back(), held);
    r.replay_speed.push_back(replay_score.speed_m_s);
    r.replay_loops.push_back(replay_score.loops);
    r.speed_vs_replay.push_back(speedVsReplay({run.hand}, {r.replay_hands.back()}, s.period_s).front());
    const Rollout ar_run = rolloutOnSim(sim, sim_data, s.period_s, w.held.start[i], ticks,
                                        [&](const JointVector& q, const std::vector<JointVector>& past) {
                                          return linearArAction(ar, q, past);
                                        });
    r.ar_dtw.push_back(nearestDemo(ar_run.hand, w.held.hand).dtw_m);
    json run_json = {{"start", w.held.names[i]},
                     {"start_q", std::vector<double>(w.held.start[i].data(), w.held.start[i].data() + kNumJoints)},
                     {"run_dir", fs::relative(job.dir, s.out).string()},
                     {"ticks", ticks},
                     {"dtw_nearest_m", near.dtw_m},
                     {"nearest_demo", w.held.names[static_cast<std::size_t>(near.index)]},
                     {"speed_m_s", r.speed.back()},
                     {"loops", r.loops.back()},
                     {"joint_range_excess_rad", r.excess.back()},
                     {"medoid", w.train.names[static_cast<std::size_t>(rep5.medoid)]},
                     {"named_demo", w.train.names[static_cast<std::size_t>(rep5.medoid)]},
                     {"code_fidelity_m", r.code_fidelity.back()},
                     {"replay_fidelity_m", r.replay_fidelity.back()},
                     {"speed_vs_replay", r.speed_vs_replay.back()},
                     {"medoid_replay_dtw_m", r.medoid_dtw.back()},
                     {"neighbour_replay_dtw_m", each},
                     {"linear_ar_dtw_m", r.ar_dtw.back()}};
    if (replay) {
      const std::vector<ReplicaTick> rep = replayAutonomousRun(s.model, s.arm, s.sim_params, w.index, w.held.start[i], ticks);
      double net2 = 0.0, act2 = 0.0, diff = 0.0;
      for (std::size_t t = 0; t < rep.size(); ++t) {
        net2 += rep[t].net.squaredNorm();
        act2 += rep[t].a.squaredNorm();
        if (t + 1 < run.q.size()) diff = std::max(diff, (rep[t].q - run.q[t + 1]).cwiseAbs().maxCoeff());
      }
      if (rep.size() + 1 != run.q.size() || diff != 0.0) ++r.replay_mismatch;
      r.share.push_back(act2 > 0.0 ? std::sqrt(net2 / act2) : 1.0);
      run_json["network_share"] = r.share.back();
      run_json["replay_max_q_difference_rad"] = diff;
      writeAblationCsv((job.dir / "ablation.csv").string(), rep);
    }
    r.runs.push_back(run_json);
  }
  r.distinct = distinctRuns(r.run_hands);
  r.replay_distinct = distinctRuns(r.replay_hands);
  return r;
}

// The reference model's runs and its baselines, per seed (detail.json "reference").
struct ReferenceScores {
  std::vector<double> ref_rmse, law_rmse, gain_rmse, ref_share;
  json runs = json::array();
};

ReferenceScores referenceScores(const Args& a, const Setup& s, const MovementWork& w, const std::vector<Job>& jobs) {
  ReferenceScores r;
  for (std::size_t k = 0; k < w.ref_jobs.size(); ++k) {
    const Job& job = jobs[w.ref_jobs[k]];
    const json summary = readSummary(job);
    if (!summary.contains("ee_rmse_m") || !summary["ee_rmse_m"].is_number())
      throw UserError((job.dir / "summary.json").string() + ": no number 'ee_rmse_m'");
    const std::string seed = "seed_" + std::to_string(a.seeds[k]);
    const fs::path dirs[3] = {job.dir, s.out / w.name / "blend_law" / seed, s.out / w.name / "gain_law" / seed};
    const double rmse[3] = {summary["ee_rmse_m"].get<double>(), w.law_rmse[k], w.gain_rmse[k]};
    for (int law = 0; law < 3; ++law) {
      (law == 0 ? r.ref_rmse : law == 1 ? r.law_rmse : r.gain_rmse).push_back(rmse[law]);
      json run = {{"law", law == 0 ? "policy" : law == 1 ? "blend" : "gain"},
                  {"seed", a.seeds[k]},
                  {"run_dir", fs::relative(dirs[law], s.out).string()},
                  {"ee_rmse_m", rmse[law]}};
      // The policy's runs: nao_rt's own network share (the evaluation laws have none).
      if (law == 0 && summary.contains("network_share") && summary["network_share"].is_number()) {
        r.ref_share.push_back(summary["network_share"].get<double>());
        run["network_share"] = r.ref_share.back();
      }
      r.runs.push_back(run);
    }
  }
  return r;
}

// One movement's entry of summary.json (docs/evaluate.md), in its key order.
json movementSummary(const Setup& s, const MovementWork& w, const HeldOutScores& held, const AutonomousScores& r,
                     const ReferenceScores& ref) {
  json m;
  m["set"] = w.set_kind;
  m["autonomous_dtw_m"] = numberOrNull(median(r.auto_dtw));
  m["medoid_replay_dtw_m"] = numberOrNull(median(r.medoid_dtw));
  m["neighbour_replay_dtw_m"] = numberOrNull(median(r.neighbour_dtw));
  m["demo_nn_dtw_m"] = numberOrNull(median(held.nn_dtw_m));
  m["linear_ar_dtw_m"] = numberOrNull(median(r.ar_dtw));
  m["speed_ratio"] = numberOrNull(median(r.speed) / median(held.speed_m_s));
  m["loops_run_median"] = numberOrNull(median(r.loops));
  m["loops_demo_median"] = numberOrNull(median(held.loops));
  m["network_share"] = r.share.empty() ? json(nullptr) : numberOrNull(median(r.share));
  m["distinct_runs"] = r.distinct;
  m["replay_distinct_runs"] = r.replay_distinct;
  m["medoid_replay_speed_ratio"] = numberOrNull(median(r.replay_speed) / median(held.speed_m_s));
  m["medoid_replay_loops_median"] = numberOrNull(median(r.replay_loops));
  m["code_fidelity_m"] = numberOrNull(median(r.code_fidelity));
  m["replay_fidelity_m"] = numberOrNull(median(r.replay_fidelity));
  m["speed_vs_replay"] = numberOrNull(median(r.speed_vs_replay));
  m["joint_range_excess_rad"] = r.excess.empty() ? 0.0 : *std::max_element(r.excess.begin(), r.excess.end());
  m["autonomous_runs"] = r.auto_dtw.size();
  m["heldout_demos"] = w.held.size();
  if (s.reference) {
    m["reference_rmse_m"] = numberOrNull(median(ref.ref_rmse));
    m["blend_law_rmse_m"] = numberOrNull(median(ref.law_rmse));
    m["gain_law_rmse_m"] = numberOrNull(median(ref.gain_rmse));
    m["reference_network_share"] = ref.ref_share.empty() ? json(nullptr) : numberOrNull(median(ref.ref_share));
    m["reference_rmse_per_seed_m"] = ref.ref_rmse;
    m["blend_law_rmse_per_seed_m"] = ref.law_rmse;
    m["gain_law_rmse_per_seed_m"] = ref.gain_rmse;
  }
  m["autonomous_dtw_per_run_m"] = r.auto_dtw;
  m["medoid_replay_dtw_per_run_m"] = r.medoid_dtw;
  m["neighbour_replay_dtw_per_run_m"] = r.neighbour_dtw;
  m["linear_ar_dtw_per_run_m"] = r.ar_dtw;
  m["code_fidelity_per_run_m"] = r.code_fidelity;
  m["replay_fidelity_per_run_m"] = r.replay_fidelity;
  m["speed_vs_replay_per_run"] = r.speed_vs_replay;
  m["demo_nn_dtw_per_demo_m"] = held.nn_dtw_m;
  return m;
}

// The movement's row of the printed table.
void printRow(const Setup& s, const MovementWork& w, const HeldOutScores& held, const AutonomousScores& r,
              const ReferenceScores& ref) {
  char loops_text[32];
  std::snprintf(loops_text, sizeof loops_text, "%.1f/%.1f", median(r.loops), median(held.loops));
  std::printf("%-10s %9s %9s %9s %9s %9s %7.2f %11s %7.3f %4zu/%-4zu %9s\n", w.name.c_str(),
              millimetres(median(r.auto_dtw)).c_str(), millimetres(median(r.medoid_dtw)).c_str(),
              millimetres(median(r.neighbour_dtw)).c_str(), millimetres(median(held.nn_dtw_m)).c_str(),
              millimetres(median(r.ar_dtw)).c_str(), median(r.speed) / median(held.speed_m_s), loops_text,
              r.share.empty() ? std::nan("") : median(r.share), r.distinct, r.auto_dtw.size(),
              s.reference ? millimetres(median(ref.ref_rmse)).c_str() : "-");
}

// summary.json's "evaluation": what was evaluated, on which demonstrations, with which baselines.
json evaluationJson(const Args& a, const Setup& s) {
  return {{"format", "nao-rt evaluate 2"},
          {"units", "m"},
          {"model", {{"path", a.model}, {"checksum", "0x" + hex64(s.model.checksum)}}},
          {"reference_model", s.reference ? json{{"path", a.reference_model}} : json(nullptr)},
          {"demo_set", s.recordings ? json{{"kind", "recordings"}, {"dir", a.recordings}}
                       : s.test     ? json{{"kind", "test"},
                                           {"test_seed", a.test_seed},
                                           {"synth_seed", kReferenceSeedBase + static_cast<std::uint64_t>(a.test_seed)},
                                           {"per_movement", a.test_demos}}
                                    : json{{"kind", "validation"}}},
          {"medoid_replay", "5 training demonstrations nearest the run's start, their medoid by summed hand-path DTW, "
                            "tracked from the run's start by a = g (f(t+1) - q)"},
          {"neighbour_replay", "each of those 5 tracked the same way; per run the median over the 5"},
          {"gain", s.gain},
          {"blend_law_pole", kFeatureBlendPole},
          {"detail", "detail.json"}};
}

void evaluate(const Args& a) {
  const Setup s = setUp(a);
  std::vector<MovementWork> work;
  std::vector<Job> jobs;
  for (std::size_t mi = 0; mi < s.model.header.movement_names.size(); ++mi)
    if (a.movement == "all" || a.movement == s.model.header.movement_names[mi])
      work.push_back(planMovement(a, s, mi, jobs));
  if (work.empty()) throw UserError("no movement to evaluate (--movement " + a.movement + ")");

  std::fprintf(stderr, "evaluate: %zu nao_rt runs, %d at a time\n", jobs.size(), a.jobs);
  runJobs(jobs, a.jobs);
  runBaselines(a, s, work);
  if (!canReplay(s.model))
    std::fprintf(stderr, "evaluate: the toolchain cannot replay this architecture's runs: no network share or ablation\n");

  const SimModel sim = makeSimModel(s.arm, s.sim_params);
  json summary, detail;
  std::printf("%-10s %9s %9s %9s %9s %9s %7s %11s %7s %9s %9s\n", "movement", "auto mm", "medoid mm", "5-near mm", "demo NN",
              "lin AR mm",
              "speed", "loops r/d", "share", "distinct", "ref mm");
  for (const MovementWork& w : work) {
    const HeldOutScores held = scoreHeldOut(w.held.hand, s.period_s);
    // The linear AR baseline: fitted on the training demonstrations, orders on the held-out ones.
    const LinearArModel ar = fitLinearAr(w.train.f, w.held.f, a.max_order);
    const AutonomousScores runs = scoreAutonomousRuns(s, sim, w, jobs, held, ar);
    const ReferenceScores ref = referenceScores(a, s, w, jobs);
    summary[w.name] = movementSummary(s, w, held, runs, ref);
    detail[w.name] = {{"heldout_demos", w.held.names},
                      {"training_demos", w.train.names},
                      {"runs", runs.runs},
                      {"replays_differing_from_nao_rt", runs.replay_mismatch},
                      {"linear_ar", arJson(ar)},
                      {"reference", ref.runs}};
    if (runs.replay_mismatch > 0)
      std::fprintf(stderr, "evaluate: %s: %zu in-process replay(s) differ from nao_rt's run (detail.json)\n",
                   w.name.c_str(), runs.replay_mismatch);
    printRow(s, w, held, runs, ref);
  }
  summary["evaluation"] = evaluationJson(a, s);
  const std::string text = summary.dump(2) + "\n", detail_text = detail.dump(2) + "\n";
  for (const auto& [file, body] : {std::pair{s.out / "summary.json", &text}, std::pair{s.out / "detail.json", &detail_text}}) {
    std::ofstream f(file, std::ios::binary | std::ios::trunc);
    f << *body;
    f.close();
    if (!f) throw UserError("cannot write " + file.string());
  }
  std::printf("evaluate: wrote %s and %s; runs in %s/<movement>/autonomous/, demonstrations in %s/<movement>/demos/\n",
              (s.out / "summary.json").string().c_str(), (s.out / "detail.json").string().c_str(), a.out.c_str(),
              a.out.c_str());
}

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "evaluate",
      "Whether an autonomous model makes its movements (docs/evaluate.md), per movement in OUT/summary.json:\n"
      "nao_rt's runs of --model from every held-out demonstration's start (the model's validation\n"
      "demonstrations, a fresh synthetic test set with --test-seed, or the held-out recordings of\n"
      "--recordings) scored by the hand-path DTW to the nearest held-out demonstration, beside the medoid\n"
      "replay (the best fixed trajectory the training data give) and the linear AR baseline; the\n"
      "middle-phase speed ratio, the loops, the joint range, the distinct runs, the network's share of\n"
      "the action and the attention ablation (ablation.csv in each run directory). With the synthetic\n"
      "data also the reference model's hand RMSE beside the blend law and the gain law.");
  auto args = std::make_shared<Args>();
  cmd->add_option("--model", args->model, "Autonomous-mode model.bin")->capture_default_str();
  cmd->add_option("--reference-model", args->reference_model, "Reference-conditioned model.bin (synthetic data only)")
      ->capture_default_str();
  cmd->add_flag("--no-reference", args->no_reference, "Skip the reference-mode runs");
  cmd->add_option("--data", args->data, "The model's data set (nao_toolchain cluster output; its fingerprint must be the model's)")
      ->capture_default_str();
  cmd->add_option("--recordings", args->recordings,
                  "A folder of recordings (<movement>_<index>/cam<k>/, docs/formats.md) the model was trained on:\n"
                  "its held-out recordings are scored, its training ones give the baselines (instead of --data)");
  cmd->add_option("--fps", args->input.fps, "Capture rate of the recordings, Hz")->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--format", args->input.format, "Keypoint layout of the recordings")
      ->check(CLI::IsMember({"body25", "body25b"}))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "Output directory")->capture_default_str();
  cmd->add_option("--urdf", args->urdf, "Robot description")->capture_default_str()->check(CLI::ExistingFile);
  cmd->add_option("--nao-rt", args->nao_rt,
                  "nao_rt executable that runs --model (default: the one beside nao_toolchain; for another\n"
                  "architecture the one toolchain/nao build --model FILE printed)");
  cmd->add_option("--reference-nao-rt", args->reference_nao_rt,
                  "nao_rt executable that runs --reference-model (default: the one beside nao_toolchain)");
  cmd->add_option("--movement", args->movement, "A movement of the model, or all")->capture_default_str();
  cmd->add_option("--seeds", args->seeds, "Run seeds of the reference-mode runs")->delimiter(',')->capture_default_str();
  cmd->add_option("--jobs", args->jobs, "nao_rt processes at a time")->check(CLI::Range(1, 64))->capture_default_str();
  cmd->add_option("--max-order", args->max_order, "Largest linear AR order tried (orders 1..N, chosen per joint)")
      ->check(CLI::Range(1, kMaxLinearArOrder))
      ->capture_default_str();
  cmd->add_option("--test-seed", args->test_seed,
                  "Score on a test set instead of the model's validation demonstrations: --test-demos fresh\n"
                  "synthetic demonstrations per movement of synthesiser run seed 1000000 + S, which neither training\n"
                  "nor model selection saw")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--test-demos", args->test_demos, "Test demonstrations per movement with --test-seed")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--min-demos", args->min_demos,
                  "Fewest held-out demonstrations per movement accepted (default: 16 for the synthetic validation set, 4 otherwise)")
      ->check(CLI::Range(1, 1000));
  cmd->callback([args] { evaluate(*args); });
}

}  // namespace

NAO_REGISTER_COMMAND(evaluate, setup)

}  // namespace nao::tools
