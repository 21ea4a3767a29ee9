// nao_toolchain evaluate: whether an autonomous model makes its movements, into OUT/summary.json
// (docs/evaluate.md). Per movement, nao_rt's runs of the model from every held-out
// demonstration's start are scored against the held-out demonstrations (hand-path DTW to the
// nearest, middle-phase speed, loops, joint range, distinct runs), against the best fixed
// trajectory the data give (the medoid replay) and the linear AR baseline; the network's share of
// the action and the attention ablation come from an in-process replay of each run through the
// runtime's own controller. With a reference model, the reference mode's hand RMSE beside the
// blend law and the gain law (nao_rt runs on recorded references).
#include "jobs.hpp"
#include "replica.hpp"

#include "nao/controller.hpp"
#include "nao/csv_reader.hpp"
#include "nao/model_metadata.hpp"
#include "nao/skeleton_csv.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/synth.hpp"
#include "rt_metrics.hpp"

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

std::vector<std::string> splitNames(const json& meta, const char* which, const std::string& movement) {
  std::vector<std::string> names;
  if (meta.is_object() && meta.contains("split") && meta["split"].contains(which) && meta["split"][which].is_array())
    for (const json& n : meta["split"][which])
      if (n.is_string() && n.get<std::string>().rfind(movement + "_", 0) == 0 &&
          n.get<std::string>().find_first_not_of("0123456789", movement.size() + 1) == std::string::npos)
        names.push_back(n.get<std::string>());
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
  std::vector<std::size_t> auto_jobs, ref_jobs, law_jobs, gain_jobs;
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

void evaluate(const Args& a) {
  if (a.seeds.empty()) throw UserError("--seeds needs at least one seed");
  const ArmModel arm = loadArmModel(a.urdf);
  // The model's runs and the reference model's may need two nao_rt builds (one per architecture).
  const fs::path beside = fs::read_symlink("/proc/self/exe").parent_path() / "nao_rt";
  const fs::path nao_rt = a.nao_rt.empty() ? beside : fs::path(a.nao_rt);
  const fs::path reference_nao_rt = a.reference_nao_rt.empty() ? beside : fs::path(a.reference_nao_rt);
  const ModelFile model = readModelFile(a.model);
  checkJointsMatch(model, arm, a.model);
  if (model.header.conditioning != Conditioning::kAutonomous)
    throw UserError(a.model + " is not an autonomous-mode model (--model)");
  const json meta = json::parse(model.header.metadata_json, nullptr, /*allow_exceptions=*/false);
  const RetargetParams retarget = modelRetargetSetting(model.header.metadata_json, RetargetParams{}, a.model);
  const ModelStarts starts = modelStarts(model.header.metadata_json, model.header.movement_names, a.model);
  const bool recordings = !a.recordings.empty();
  const bool test = a.test_seed >= 0;
  if (recordings && test) throw UserError("--test-seed scores a synthetic test set; --recordings scores the model's held-out recordings: take one");
  const bool reference = !recordings && !a.no_reference;
  // The reference model's nao_rt is needed only where it runs.
  std::vector<std::pair<fs::path, const char*>> exes{{nao_rt, "--nao-rt"}};
  if (reference) exes.emplace_back(reference_nao_rt, "--reference-nao-rt");
  for (const auto& [exe, option] : exes)
    if (access(exe.c_str(), X_OK) != 0)
      throw UserError("nao_rt not found at " + exe.string() + ": build it (toolchain/nao build) or pass " + option +
                      " PATH");
  const int min_demos = a.min_demos > 0 ? a.min_demos : (!recordings && !test ? 16 : 4);

  std::unique_ptr<PolicyData> data;
  if (!recordings) {
    std::error_code ec;
    if (!fs::is_directory(a.data, ec))
      throw UserError(a.data + ": no data set (toolchain/nao train data makes it; the baselines are fitted on the model's training demonstrations)");
    std::fprintf(stderr, "evaluate: reading the data set %s\n", a.data.c_str());
    data = std::make_unique<PolicyData>(loadPolicyData(a.data));
    const std::string have = hex64(dataFingerprint(*data));
    const std::string want = meta.contains("data") && meta["data"].contains("fingerprint") && meta["data"]["fingerprint"].is_string()
                                 ? meta["data"]["fingerprint"].get<std::string>()
                                 : std::string("an unrecorded one");
    if (have != want)
      throw UserError(a.data + " has data fingerprint " + have + ", " + a.model + " was trained on " + want +
                      " (toolchain/nao train data rebuilds the data set)");
  }

  const fs::path out(a.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw UserError("cannot create " + a.out + ": " + ec.message());
  const SimParams sim_params;
  const SimModel sim = makeSimModel(arm, sim_params);
  const double period_s = ControllerParams{}.period_s;
  const double gain = servoStepGain(sim.params);

  std::vector<MovementWork> work;
  std::vector<Job> jobs;
  const std::vector<std::string>& names = model.header.movement_names;
  for (std::size_t mi = 0; mi < names.size(); ++mi) {
    const std::string& name = names[mi];
    if (a.movement != "all" && a.movement != name) continue;
    MovementWork w;
    w.name = name;
    w.index = static_cast<int>(mi);
    const std::vector<JointVector> key_poses = modelKeyPoses(model, w.index);
    const std::vector<std::string> val_names = splitNames(meta, "val", name), train_names = splitNames(meta, "train", name);
    if (recordings) {
      w.set_kind = "recordings";
      w.held = demoSetFromRecordings(arm, a.recordings, val_names, a.input, retarget, key_poses, name + " held out");
      w.train = demoSetFromRecordings(arm, a.recordings, train_names, a.input, retarget, key_poses, name + " training");
    } else {
      w.train = demoSetFrom(arm, *data, name, train_names);
      if (test) {
        w.set_kind = "test";
        w.held = syntheticTestSet(arm, name, static_cast<std::uint64_t>(a.test_seed), a.test_demos,
                                  out / "test_recordings" / name, a.input, retarget, key_poses);
      } else {
        w.set_kind = "validation";
        w.held = demoSetFrom(arm, *data, name, val_names);
      }
    }
    if (static_cast<int>(w.held.size()) < min_demos)
      throw UserError(a.model + ": " + std::to_string(w.held.size()) + " held-out demonstration(s) of " + name +
                      "; this evaluation needs at least " + std::to_string(min_demos) + " (--min-demos)");
    if (w.train.size() == 0) throw UserError(a.model + ": no training demonstration of " + name + " (split.train)");
    // A validation demonstration is one of the model's starts: nao_rt runs it with --start I.
    for (const std::string& n : w.held.names) {
      int index = -1;
      if (w.set_kind != "test")
        for (std::size_t i = 0; i < starts[mi].size(); ++i)
          if (starts[mi][i].name == n) index = static_cast<int>(i);
      w.start_index.push_back(index);
    }

    const fs::path mdir = out / name;
    for (const char* sub : {"autonomous", "reference", "blend_law", "gain_law", "references", "demos"})
      fs::remove_all(mdir / sub, ec);
    fs::create_directories(mdir / "demos", ec);
    for (std::size_t i = 0; i < w.held.size(); ++i) {
      writeTrajectoryCsv((mdir / "demos" / (w.held.names[i] + ".csv")).string(), w.held.f[i], period_s);
      std::vector<std::string> argv = {nao_rt.string(), "--weights", a.model, "--urdf", a.urdf,
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
    if (reference) {
      char pole_text[32], gain_text[32];
      std::snprintf(pole_text, sizeof pole_text, "%.17g", kFeatureBlendPole);
      std::snprintf(gain_text, sizeof gain_text, "%.17g", gain);
      for (std::uint64_t s : a.seeds) {
        const std::string seed = std::to_string(s);
        // The reference: demonstration 0 of run seed 1000000 + s (never a training seed) as the two
        // cameras and the triangulation see it, written exactly (17 digits).
        const fs::path skeleton = mdir / "references" / ("seed_" + seed + ".csv");
        fs::create_directories(skeleton.parent_path(), ec);
        writeSkeletonCsv(skeleton.string(), observeDemo(generateDemo(parseMovement(name), 0, kReferenceSeedBase + s, false)),
                         false, 17);
        const auto referenceRun = [&](const std::string& label, const char* sub, std::vector<std::string> extra) {
          const fs::path dir = mdir / sub / ("seed_" + seed);
          std::vector<std::string> argv = {reference_nao_rt.string(), "--weights", a.reference_model, "--urdf", a.urdf,
                                           "--reference", "file:" + skeleton.string(), "--movement", name};
          argv.insert(argv.end(), extra.begin(), extra.end());
          for (const char* x : {"--zero-timing", "--log"}) argv.push_back(x);
          argv.push_back(dir.string());
          jobs.push_back({name + " " + label + " seed " + seed, argv, dir});
          return jobs.size() - 1;
        };
        w.ref_jobs.push_back(referenceRun("reference", "reference", {}));
        w.law_jobs.push_back(referenceRun("blend law", "blend_law", {"--blend-law-pole", pole_text}));
        w.gain_jobs.push_back(referenceRun("gain law", "gain_law", {"--gain-law", gain_text}));
      }
    }
    work.push_back(std::move(w));
  }
  if (work.empty()) throw UserError("no movement to evaluate (--movement " + a.movement + ")");

  std::fprintf(stderr, "evaluate: %zu nao_rt runs, %d at a time\n", jobs.size(), a.jobs);
  runJobs(jobs, a.jobs);
  const bool replay = canReplay(model);
  if (!replay)
    std::fprintf(stderr, "evaluate: the toolchain cannot replay this architecture's runs: no network share or ablation\n");

  json summary, detail;
  std::printf("%-10s %9s %9s %9s %9s %9s %7s %11s %7s %9s %9s\n", "movement", "auto mm", "medoid mm", "5-near mm", "demo NN",
              "lin AR mm",
              "speed", "loops r/d", "share", "distinct", "ref mm");
  for (const MovementWork& w : work) {
    const fs::path mdir = out / w.name;
    // The demonstrations' joint range (held out and training: their trajectories and the starts
    // they begin at) and the plane loops are counted in.
    JointVector lo = JointVector::Constant(1e9), hi = JointVector::Constant(-1e9);
    for (const DemoSet* s : {&w.held, &w.train}) {
      for (const auto& f : s->f)
        for (const JointVector& q : f) {
          lo = lo.cwiseMin(q);
          hi = hi.cwiseMax(q);
        }
      for (const JointVector& q : s->start) {
        lo = lo.cwiseMin(q);
        hi = hi.cwiseMax(q);
      }
    }
    const HeldOutScores held = scoreHeldOut(w.held.hand, period_s);
    // The linear AR baseline: fitted on the training demonstrations, orders on the held-out ones.
    const LinearArModel ar = fitLinearAr(w.train.f, w.held.f, a.max_order);
    SimData sim_data(sim, w.held.start.front());

    std::vector<double> auto_dtw, medoid_dtw, neighbour_dtw, ar_dtw, speed, loops, share, excess;
    std::vector<double> code_fidelity, replay_fidelity, replay_speed, replay_loops;
    std::vector<HandPath> run_hands, replay_hands;
    json runs = json::array();
    std::size_t replay_mismatch = 0;
    for (std::size_t i = 0; i < w.held.size(); ++i) {
      const Job& job = jobs[w.auto_jobs[i]];
      const json s = readSummary(job);
      const int ticks = static_cast<int>(w.held.f[i].size());
      if (!s.contains("ticks") || s["ticks"] != ticks)
        throw UserError((job.dir / "summary.json").string() + ": not the run of " + w.held.names[i]);
      const RunPaths run = readRun(arm, w.held.start[i], job.dir / "ticks.csv");
      const RunScore score = scoreRun(run.hand, held);
      const NearestDemo& near = score.nearest;
      auto_dtw.push_back(near.dtw_m);
      speed.push_back(score.speed_m_s);
      loops.push_back(score.loops);
      excess.push_back(rangeExcess(run.q, lo, hi));
      run_hands.push_back(run.hand);
      const NeighbourReplays rep5 = neighbourReplays(sim, period_s, gain, w.train, w.held.start[i], ticks);
      std::vector<double> each;  // in rep5.demos' order, the medoid among them
      for (const std::vector<JointVector>& q : rep5.q) each.push_back(nearestDemo(handPath(arm, q), w.held.hand).dtw_m);
      medoid_dtw.push_back(each[rep5.medoidSlot()]);
      neighbour_dtw.push_back(median(each));
      // What the run plays: the named demonstration (the medoid, whose code a run-code model's
      // run takes), and how far the run and the medoid replay are from it.
      const HandPath& named = w.train.hand[static_cast<std::size_t>(rep5.medoid)];
      replay_hands.push_back(handPath(arm, rep5.medoidQ()));
      code_fidelity.push_back(rt::dtwMeanDistance(run.hand, named));
      replay_fidelity.push_back(rt::dtwMeanDistance(replay_hands.back(), named));
      const RunScore replay_score = scoreRun(replay_hands.back(), held);
      replay_speed.push_back(replay_score.speed_m_s);
      replay_loops.push_back(replay_score.loops);
      const Rollout ar_run = rolloutOnSim(sim, sim_data, period_s, w.held.start[i], ticks,
                                          [&](const JointVector& q, const std::vector<JointVector>& past) {
                                            return linearArAction(ar, q, past);
                                          });
      ar_dtw.push_back(nearestDemo(ar_run.hand, w.held.hand).dtw_m);
      json r = {{"start", w.held.names[i]},
                {"start_q", std::vector<double>(w.held.start[i].data(), w.held.start[i].data() + kNumJoints)},
                {"run_dir", fs::relative(job.dir, out).string()},
                {"ticks", ticks},
                {"dtw_nearest_m", near.dtw_m},
                {"nearest_demo", w.held.names[static_cast<std::size_t>(near.index)]},
                {"speed_m_s", speed.back()},
                {"loops", loops.back()},
                {"joint_range_excess_rad", excess.back()},
                {"medoid", w.train.names[static_cast<std::size_t>(rep5.medoid)]},
                {"named_demo", w.train.names[static_cast<std::size_t>(rep5.medoid)]},
                {"code_fidelity_m", code_fidelity.back()},
                {"replay_fidelity_m", replay_fidelity.back()},
                {"medoid_replay_dtw_m", medoid_dtw.back()},
                {"neighbour_replay_dtw_m", each},
                {"linear_ar_dtw_m", ar_dtw.back()}};
      if (replay) {
        const std::vector<ReplicaTick> rep = replayAutonomousRun(model, arm, sim_params, w.index, w.held.start[i], ticks);
        double net2 = 0.0, act2 = 0.0, diff = 0.0;
        for (std::size_t t = 0; t < rep.size(); ++t) {
          net2 += rep[t].net.squaredNorm();
          act2 += rep[t].a.squaredNorm();
          if (t + 1 < run.q.size()) diff = std::max(diff, (rep[t].q - run.q[t + 1]).cwiseAbs().maxCoeff());
        }
        if (rep.size() + 1 != run.q.size() || diff != 0.0) ++replay_mismatch;
        share.push_back(act2 > 0.0 ? std::sqrt(net2 / act2) : 1.0);
        r["network_share"] = share.back();
        r["replay_max_q_difference_rad"] = diff;
        writeAblationCsv((job.dir / "ablation.csv").string(), rep);
      }
      runs.push_back(r);
    }
    const std::size_t distinct = distinctRuns(run_hands), replay_distinct = distinctRuns(replay_hands);
    std::vector<double> ref_rmse, law_rmse, gain_rmse, ref_share;
    json ref_runs = json::array();
    for (std::size_t k = 0; k < w.ref_jobs.size(); ++k)
      for (int law = 0; law < 3; ++law) {
        const std::vector<std::size_t>& list = law == 0 ? w.ref_jobs : law == 1 ? w.law_jobs : w.gain_jobs;
        const Job& job = jobs[list[k]];
        const json s = readSummary(job);
        if (!s.contains("ee_rmse_m") || !s["ee_rmse_m"].is_number())
          throw UserError((job.dir / "summary.json").string() + ": no number 'ee_rmse_m'");
        const double rmse = s["ee_rmse_m"].get<double>();
        (law == 0 ? ref_rmse : law == 1 ? law_rmse : gain_rmse).push_back(rmse);
        json run = {{"law", law == 0 ? "policy" : law == 1 ? "blend" : "gain"},
                    {"seed", a.seeds[k]},
                    {"run_dir", fs::relative(job.dir, out).string()},
                    {"ee_rmse_m", rmse}};
        // The policy's runs: nao_rt's own network share (the evaluation laws have none).
        if (law == 0 && s.contains("network_share") && s["network_share"].is_number()) {
          ref_share.push_back(s["network_share"].get<double>());
          run["network_share"] = ref_share.back();
        }
        ref_runs.push_back(run);
      }

    json m;
    m["set"] = w.set_kind;
    m["autonomous_dtw_m"] = numberOrNull(median(auto_dtw));
    m["medoid_replay_dtw_m"] = numberOrNull(median(medoid_dtw));
    m["neighbour_replay_dtw_m"] = numberOrNull(median(neighbour_dtw));
    m["demo_nn_dtw_m"] = numberOrNull(median(held.nn_dtw_m));
    m["linear_ar_dtw_m"] = numberOrNull(median(ar_dtw));
    m["speed_ratio"] = numberOrNull(median(speed) / median(held.speed_m_s));
    m["loops_run_median"] = numberOrNull(median(loops));
    m["loops_demo_median"] = numberOrNull(median(held.loops));
    m["network_share"] = share.empty() ? json(nullptr) : numberOrNull(median(share));
    m["distinct_runs"] = distinct;
    m["replay_distinct_runs"] = replay_distinct;
    m["medoid_replay_speed_ratio"] = numberOrNull(median(replay_speed) / median(held.speed_m_s));
    m["medoid_replay_loops_median"] = numberOrNull(median(replay_loops));
    m["code_fidelity_m"] = numberOrNull(median(code_fidelity));
    m["replay_fidelity_m"] = numberOrNull(median(replay_fidelity));
    m["joint_range_excess_rad"] = excess.empty() ? 0.0 : *std::max_element(excess.begin(), excess.end());
    m["autonomous_runs"] = auto_dtw.size();
    m["heldout_demos"] = w.held.size();
    if (reference) {
      m["reference_rmse_m"] = numberOrNull(median(ref_rmse));
      m["blend_law_rmse_m"] = numberOrNull(median(law_rmse));
      m["gain_law_rmse_m"] = numberOrNull(median(gain_rmse));
      m["reference_network_share"] = ref_share.empty() ? json(nullptr) : numberOrNull(median(ref_share));
      m["reference_rmse_per_seed_m"] = ref_rmse;
      m["blend_law_rmse_per_seed_m"] = law_rmse;
      m["gain_law_rmse_per_seed_m"] = gain_rmse;
    }
    m["autonomous_dtw_per_run_m"] = auto_dtw;
    m["medoid_replay_dtw_per_run_m"] = medoid_dtw;
    m["neighbour_replay_dtw_per_run_m"] = neighbour_dtw;
    m["linear_ar_dtw_per_run_m"] = ar_dtw;
    m["code_fidelity_per_run_m"] = code_fidelity;
    m["replay_fidelity_per_run_m"] = replay_fidelity;
    m["demo_nn_dtw_per_demo_m"] = held.nn_dtw_m;
    summary[w.name] = m;
    detail[w.name] = {{"heldout_demos", w.held.names},
                      {"training_demos", w.train.names},
                      {"runs", runs},
                      {"replays_differing_from_nao_rt", replay_mismatch},
                      {"linear_ar", arJson(ar)},
                      {"reference", ref_runs}};
    if (replay_mismatch > 0)
      std::fprintf(stderr, "evaluate: %s: %zu in-process replay(s) differ from nao_rt's run (detail.json)\n",
                   w.name.c_str(), replay_mismatch);
    char loops_text[32];
    std::snprintf(loops_text, sizeof loops_text, "%.1f/%.1f", median(loops), median(held.loops));
    std::printf("%-10s %9s %9s %9s %9s %9s %7.2f %11s %7.3f %4zu/%-4zu %9s\n", w.name.c_str(),
                millimetres(median(auto_dtw)).c_str(), millimetres(median(medoid_dtw)).c_str(),
                millimetres(median(neighbour_dtw)).c_str(),
                millimetres(median(held.nn_dtw_m)).c_str(), millimetres(median(ar_dtw)).c_str(),
                median(speed) / median(held.speed_m_s),
                loops_text, share.empty() ? std::nan("") : median(share), distinct, auto_dtw.size(),
                reference ? millimetres(median(ref_rmse)).c_str() : "-");
  }
  summary["evaluation"] = {
      {"format", "nao-rt evaluate 2"},
      {"units", "m"},
      {"model", {{"path", a.model}, {"checksum", "0x" + hex64(model.checksum)}}},
      {"reference_model", reference ? json{{"path", a.reference_model}} : json(nullptr)},
      {"demo_set", recordings ? json{{"kind", "recordings"}, {"dir", a.recordings}}
                   : test     ? json{{"kind", "test"},
                                     {"test_seed", a.test_seed},
                                     {"synth_seed", kReferenceSeedBase + static_cast<std::uint64_t>(a.test_seed)},
                                     {"per_movement", a.test_demos}}
                              : json{{"kind", "validation"}}},
      {"medoid_replay", "5 training demonstrations nearest the run's start, their medoid by summed hand-path DTW, "
                        "tracked from the run's start by a = g (f(t+1) - q)"},
      {"neighbour_replay", "each of those 5 tracked the same way; per run the median over the 5"},
      {"gain", gain},
      {"blend_law_pole", kFeatureBlendPole},
      {"detail", "detail.json"}};
  const std::string text = summary.dump(2) + "\n", detail_text = detail.dump(2) + "\n";
  for (const auto& [file, body] : {std::pair{out / "summary.json", &text}, std::pair{out / "detail.json", &detail_text}}) {
    std::ofstream f(file, std::ios::binary | std::ios::trunc);
    f << *body;
    f.close();
    if (!f) throw UserError("cannot write " + file.string());
  }
  std::printf("evaluate: wrote %s and %s; runs in %s/<movement>/autonomous/, demonstrations in %s/<movement>/demos/\n",
              (out / "summary.json").string().c_str(), (out / "detail.json").string().c_str(), a.out.c_str(),
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
