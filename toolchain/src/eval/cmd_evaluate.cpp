// nao_toolchain evaluate: issue 13's scores per movement into OUT/summary.json (docs/evaluate.md).
//
//   autonomous_dtw_m   median over the held-out demonstrations d of nao_rt's rollout of the
//                      autonomous model from d's s_0 for d's length (--reference none
//                      --start-pose s_0 --ticks N): DTW of its hand path (ticks.csv) to the
//                      nearest held-out demonstration
//   demo_nn_dtw_m      median over d of the DTW from d to its nearest other held-out demonstration
//   linear_ar_dtw_m    the per-joint linear AR baseline (linear_ar.hpp), fitted on the model's
//                      training split, rolled out from the same s_0 on the same simulated arm
//   reference_rmse_m   median over --seeds of nao_rt's hand RMSE in reference mode with the
//                      reference model, on the held-out demonstration of synthesiser run seed
//                      1000000 + s, written as a skeleton CSV (--reference file:PATH)
//   blend_law_rmse_m   the same run with the blend law instead of the policy (--blend-law-pole)
//   gain_law_rmse_m    the same run with the fixed-gain first-order servo inversion (--gain-law):
//                      the closed form the execution labels would follow on an exactly
//                      first-order arm, i.e. the bar for what the policy learns beyond a formula
#include "nao/controller.hpp"
#include "nao/csv_reader.hpp"
#include "nao/kinematics.hpp"
#include "nao/model_file.hpp"
#include "nao/model_metadata.hpp"
#include "nao/sim_arm.hpp"
#include "nao/skeleton_csv.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/heldout.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/synth.hpp"
#include "rt_metrics.hpp"

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

extern char** environ;

namespace nao::tools {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

struct Args {
  std::string autonomous_model = "models/autonomous.bin";
  std::string reference_model = "models/default.bin";
  std::string data = "out/train/data";
  std::string out = "out/eval";
  std::string urdf = NAO_DEFAULT_URDF;
  std::string nao_rt;
  std::string movement = "all";
  std::vector<std::uint64_t> seeds = {1, 2, 3, 4, 5};
  int jobs = 2;
  int max_order = 12;
  int min_demos = 16;
  std::int64_t test_seed = -1;  ///< >= 0: score on the test set of this seed (testDemos), not on validation
  int test_demos = 16;
  bool data_given = false;
};

// The linear AR baseline of one movement, fitted one way, rolled out from every held-out s_0.
struct ArBaseline {
  bool paced = false;  ///< fitted on the trajectories at the model's canonical pace
  LinearArModel model;
  std::vector<NearestDemo> nearest;
  std::vector<int> limited;
  std::vector<double> dtw;  ///< nearest[i].dtw_m
};

// One nao_rt process of the evaluation.
struct Job {
  std::string what;               // for progress and errors, e.g. "elbow autonomous elbow_012"
  std::vector<std::string> argv;  // argv[0] = nao_rt
  fs::path dir;                   // run directory (--log), holds nao_rt.log
};

std::string readText(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

std::string lastLine(const std::string& text) {
  std::istringstream in(text);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last;
}

pid_t spawn(const Job& job) {
  std::error_code ec;
  fs::create_directories(job.dir, ec);
  if (ec) throw UserError("cannot create " + job.dir.string() + ": " + ec.message());
  const std::string log = (job.dir / "nao_rt.log").string();
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<char*> argv;
  for (const std::string& a : job.argv) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw UserError("cannot start " + job.argv[0] + ": " + std::strerror(rc));
  return pid;
}

// Runs the jobs, at most `parallel` at a time. On the first failure no new job starts; the
// running ones finish, then the failure is reported (nao_rt's own last line).
void runJobs(const std::vector<Job>& jobs, int parallel) {
  std::map<pid_t, std::size_t> running;
  std::size_t next = 0, done = 0;
  std::string failure;
  while (done < jobs.size()) {
    while (failure.empty() && next < jobs.size() && static_cast<int>(running.size()) < parallel) {
      running[spawn(jobs[next])] = next;
      ++next;
    }
    if (running.empty()) break;
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) throw UserError(std::string("waiting for nao_rt: ") + std::strerror(errno));
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const Job& job = jobs[it->second];
    running.erase(it);
    ++done;
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    std::fprintf(stderr, "evaluate: [%zu/%zu] %s%s\n", done, jobs.size(), job.what.c_str(), ok ? "" : " FAILED");
    if (!ok && failure.empty()) {
      const std::string line = lastLine(readText(job.dir / "nao_rt.log"));
      failure = job.what + ": nao_rt " +
                (WIFEXITED(status) ? "exit " + std::to_string(WEXITSTATUS(status)) : std::string("killed")) + ": " +
                (line.empty() ? "(no output)" : line) + " (log: " + (job.dir / "nao_rt.log").string() + ")";
    }
  }
  if (!failure.empty()) throw UserError(failure);
}

json readSummary(const Job& job) {
  const fs::path p = job.dir / "summary.json";
  const json j = json::parse(readText(p), nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw UserError(p.string() + ": not a JSON object (nao_rt did not finish?)");
  return j;
}

double numberAt(const json& j, const char* key, const Job& job) {
  if (!j.contains(key) || !j[key].is_number())
    throw UserError((job.dir / "summary.json").string() + ": no number '" + key + "'");
  return j[key].get<double>();
}

json metadataOf(const ModelFile& m) {
  return json::parse(m.header.metadata_json, nullptr, /*allow_exceptions=*/false);
}

std::vector<std::string> splitNames(const json& meta, const char* which) {
  std::vector<std::string> names;
  if (meta.is_object() && meta.contains("split") && meta["split"].contains(which) && meta["split"][which].is_array())
    for (const json& n : meta["split"][which])
      if (n.is_string()) names.push_back(n.get<std::string>());
  return names;
}

// "<movement>_<index>" of `movement`: the index, or -1.
int demoIndex(const std::string& name, const std::string& movement) {
  const auto cut = name.rfind('_');
  if (cut == std::string::npos || name.substr(0, cut) != movement) return -1;
  const std::string digits = name.substr(cut + 1);
  if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) return -1;
  return std::stoi(digits);
}

std::string millimetres(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", m * 1e3);
  return buf;
}

json numberOrNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

std::string exactNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// The hand path of a nao_rt run: the start pose's hand point (at rest, clamped to the limits),
// then every tick's hand point (ticks.csv ee_x, ee_y, ee_z: exact doubles).
HandPath runHandPath(const ArmModel& arm, const JointVector& q_start, const fs::path& ticks_csv) {
  HandPath path = handPath(arm, {clampToLimits(arm, q_start)});
  CsvReader csv(ticks_csv.string(), "ticks.csv");
  const std::size_t x = csv.column("ee_x"), y = csv.column("ee_y"), z = csv.column("ee_z");
  while (csv.next()) path.emplace_back(csv.number(x), csv.number(y), csv.number(z));
  return path;
}

json arJson(const LinearArModel& m) {
  json joints = json::array();
  for (const LinearArJoint& j : m.joints)
    joints.push_back({{"order", j.order},
                      {"c", j.c},
                      {"beta", j.beta},
                      {"alpha", j.alpha},
                      {"train_mse_rad2", j.train_mse},
                      {"val_mse_by_order_rad2", j.val_mse_by_order}});
  return joints;
}

void evaluate(const Args& a) {
  if (a.jobs < 1) throw UserError("--jobs must be at least 1");
  if (a.seeds.empty()) throw UserError("--seeds needs at least one seed");
  const ArmModel arm = loadArmModel(a.urdf);
  const fs::path nao_rt = a.nao_rt.empty() ? fs::read_symlink("/proc/self/exe").parent_path() / "nao_rt" : fs::path(a.nao_rt);
  if (access(nao_rt.c_str(), X_OK) != 0)
    throw UserError("nao_rt not found at " + nao_rt.string() + ": build it (toolchain/nao build) or pass --nao-rt PATH");

  const ModelFile auto_model = readModelFile(a.autonomous_model);
  const ModelFile ref_model = readModelFile(a.reference_model);
  checkJointsMatch(auto_model, arm, a.autonomous_model);
  checkJointsMatch(ref_model, arm, a.reference_model);
  if (auto_model.header.conditioning != Conditioning::kAutonomous)
    throw UserError(a.autonomous_model + " is not an autonomous-mode model (--autonomous-model)");
  if (ref_model.header.conditioning != Conditioning::kReference)
    throw UserError(a.reference_model + " is not a reference-conditioned model (--reference-model)");
  const json meta = metadataOf(auto_model);
  const json ref_meta = metadataOf(ref_model);
  const RetargetParams retarget = modelRetargetSetting(auto_model.header.metadata_json, RetargetParams{},
                                                       a.autonomous_model);
  double pole = KeyPoseBlend{}.pole;
  if (ref_meta.is_object() && ref_meta.contains("training") && ref_meta["training"].contains("perturbation") &&
      ref_meta["training"]["perturbation"].contains("blend_pole") &&
      ref_meta["training"]["perturbation"]["blend_pole"].is_number())
    pole = ref_meta["training"]["perturbation"]["blend_pole"].get<double>();

  // The AR baseline's training data: the autonomous model's own data set when it is here (its
  // fingerprint must be the model's), else its training demonstrations regenerated.
  std::unique_ptr<PolicyData> data;
  std::string data_source = "regenerated";
  if (a.data != "regenerate") {
    if (fs::is_directory(a.data)) {
      std::fprintf(stderr, "evaluate: reading the training data set %s\n", a.data.c_str());
      data = std::make_unique<PolicyData>(loadPolicyData(a.data));
      const std::string have = hex64(dataFingerprint(*data));
      std::string want;
      if (meta.contains("data") && meta["data"].contains("fingerprint") && meta["data"]["fingerprint"].is_string())
        want = meta["data"]["fingerprint"].get<std::string>();
      if (have != want)
        throw UserError(a.data + " has data fingerprint " + have + ", " + a.autonomous_model + " was trained on " +
                        (want.empty() ? std::string("an unrecorded one") : want) +
                        ": rebuild it (toolchain/nao train data) or pass --data regenerate");
      data_source = a.data + " (fingerprint " + have + ")";
    } else if (a.data_given) {
      throw UserError("--data " + a.data + " is not a directory (a data set of nao_toolchain cluster, or 'regenerate')");
    } else {
      std::fprintf(stderr,
                   "evaluate: no data set at %s (toolchain/nao train data makes it): the linear AR baseline is fitted "
                   "on the training demonstrations regenerated like nao_rt regenerates held-out ones\n",
                   a.data.c_str());
    }
  }

  const fs::path out(a.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw UserError("cannot create " + a.out + ": " + ec.message());

  const std::vector<std::string> train_names = splitNames(meta, "train");
  const SimModel sim = makeSimModel(arm, SimParams{});
  const double period_s = ControllerParams{}.period_s;
  // The gain that inverts the simulated first-order servo over one tick (the expert's first step).
  const double gain = servoStepGain(sim.params);

  struct MovementWork {
    std::string name;
    HeldOutDemos held;
    std::vector<NearestDemo> demo_nn;
    // [0]: fitted on the demonstrations as they are; [1]: on them at the model's canonical pace
    // (only for such a model). The bar is the better of the two.
    std::vector<ArBaseline> ar;
    std::size_t ar_train_demos = 0;
    std::vector<std::size_t> auto_jobs, ref_jobs, law_jobs, gain_jobs;
  };
  std::vector<MovementWork> work;
  std::vector<Job> jobs;
  for (const char* mname : kMovementNames) {
    const std::string name = mname;
    if (a.movement != "all" && a.movement != name) continue;
    const auto& names = auto_model.header.movement_names;
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      if (a.movement != "all") throw UserError(a.autonomous_model + " has no movement '" + name + "'");
      continue;
    }
    MovementWork w;
    w.name = name;
    // v: the model's validation demonstrations (the AR order is chosen on them); scored: the ones
    // scored, v itself, or with --test-seed a test set that neither training nor selection saw.
    const ValidationSet v = validationDemos(auto_model.header.metadata_json, name, a.autonomous_model);
    const bool test = a.test_seed >= 0;
    const ValidationSet scored = test ? testDemos(name, static_cast<std::uint64_t>(a.test_seed), a.test_demos) : v;
    if (!test && static_cast<int>(v.names.size()) < a.min_demos)
      throw UserError(a.autonomous_model + " holds out " + std::to_string(v.names.size()) + " demonstration(s) of " +
                      name + "; the protocol needs at least " + std::to_string(a.min_demos) +
                      " (--min-demos; retrain with a larger validation fraction)");
    const std::vector<JointVector> key_poses = modelKeyPoses(auto_model, static_cast<int>(it - names.begin()));
    w.held.movement = name;
    w.held.seed = scored.seed;
    w.held.seed_assumed = scored.seed_assumed;
    w.held.names = scored.names;
    w.held.indices = scored.indices;
    std::fprintf(stderr, "evaluate: %s: regenerating %zu %s demonstrations (synth seed %llu)\n", name.c_str(),
                 scored.names.size(), test ? "test" : "held-out", static_cast<unsigned long long>(scored.seed));
    w.held.target = regenerateTargets(arm, name, scored.seed, scored.indices, key_poses, retarget);
    for (const auto& t : w.held.target) w.held.hand.push_back(handPath(arm, t));
    for (std::size_t i = 0; i < w.held.hand.size(); ++i)
      w.demo_nn.push_back(nearestDemo(w.held.hand[i], w.held.hand, static_cast<int>(i)));

    // Linear AR: fitted on the training split, order chosen on the held-out split (one step).
    std::vector<std::vector<JointVector>> train, val;
    std::vector<std::string> train_of;  // the name of every entry of train
    if (data) {
      const std::set<std::string> want_train(train_names.begin(), train_names.end());
      const std::set<std::string> want_val(v.names.begin(), v.names.end());
      for (const PolicyDemo& d : data->demos) {
        if (demoIndex(d.name, name) < 0) continue;
        if (want_train.count(d.name)) {
          train.push_back(d.f);
          train_of.push_back(d.name);
        }
        if (want_val.count(d.name)) val.push_back(d.f);
      }
    } else {
      std::vector<int> idx;
      for (const std::string& n : train_names)
        if (demoIndex(n, name) >= 0) {
          idx.push_back(demoIndex(n, name));
          train_of.push_back(n);
        }
      std::fprintf(stderr, "evaluate: %s: regenerating %zu training demonstrations\n", name.c_str(), idx.size());
      train = regenerateTargets(arm, name, v.seed, idx, key_poses, retarget);
      val = test ? regenerateTargets(arm, name, v.seed, v.indices, key_poses, retarget) : w.held.target;
    }
    if (train.empty()) throw UserError(a.autonomous_model + ": no training demonstration of " + name + " (split.train)");
    if (val.empty()) throw UserError("no held-out demonstration of " + name + " in the data set " + a.data);
    w.ar_train_demos = train.size();
    SimData sim_data(sim, w.held.target.front().front());
    for (int paced = 0; paced <= 0; ++paced) {
      ArBaseline b;
      b.paced = paced != 0;
      b.model = fitLinearAr(train, val, a.max_order);
      for (std::size_t i = 0; i < w.held.target.size(); ++i) {
        const Rollout r = rolloutOnSim(sim, sim_data, period_s, w.held.target[i].front(),
                                       static_cast<int>(w.held.target[i].size()),
                                       [&](const JointVector& q, const std::vector<JointVector>& a_past) {
                                         return linearArAction(b.model, q, a_past);
                                       });
        b.nearest.push_back(nearestDemo(r.hand, w.held.hand));
        b.limited.push_back(r.limited_ticks);
        b.dtw.push_back(b.nearest.back().dtw_m);
      }
      w.ar.push_back(std::move(b));
    }

    // nao_rt runs: one autonomous rollout per held-out demonstration, reference mode per seed.
    const fs::path mdir = out / name;
    for (const char* sub : {"autonomous", "reference", "blend_law", "gain_law", "references"})
      fs::remove_all(mdir / sub, ec);
    for (std::size_t i = 0; i < scored.names.size(); ++i) {
      // From the demonstration's s_0 (its feature-extracted start, at rest) for its length.
      w.auto_jobs.push_back(jobs.size());
      const JointVector& s0 = w.held.target[i].front();
      std::string pose;
      for (int j = 0; j < kNumJoints; ++j) pose += (j > 0 ? "," : "") + exactNumber(s0[j]);
      std::vector<std::string> argv = {nao_rt.string(), "--weights", a.autonomous_model, "--urdf", a.urdf,
                                       "--reference", "none", "--movement", name, "--start-pose", pose,
                                       "--ticks", std::to_string(w.held.target[i].size()),
                                       "--zero-timing", "--log", (mdir / "autonomous" / scored.names[i]).string()};
      jobs.push_back({name + " autonomous " + scored.names[i], argv, mdir / "autonomous" / scored.names[i]});
    }
    char pole_text[32], gain_text[32];
    std::snprintf(pole_text, sizeof pole_text, "%.17g", pole);
    std::snprintf(gain_text, sizeof gain_text, "%.17g", gain);
    for (std::uint64_t s : a.seeds) {
      const std::string seed = std::to_string(s);
      // The reference: demonstration 0 of run seed 1000000 + s (never a training seed) as the
      // two cameras and the triangulation see it, written exactly (17 digits).
      const fs::path skeleton = mdir / "references" / ("seed_" + seed + ".csv");
      fs::create_directories(skeleton.parent_path(), ec);
      writeSkeletonCsv(skeleton.string(),
                       observeDemo(generateDemo(parseMovement(name), 0, kReferenceSeedBase + s, false)), false, 17);
      // One reference-mode run of the model (no extra flags) or of a baseline replacing it.
      const auto referenceRun = [&](const std::string& label, const char* sub, std::vector<std::string> extra) {
        const fs::path dir = mdir / sub / ("seed_" + seed);
        std::vector<std::string> argv = {nao_rt.string(), "--weights", a.reference_model, "--urdf", a.urdf,
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
    work.push_back(std::move(w));
  }
  if (work.empty()) throw UserError("no movement to evaluate");

  std::fprintf(stderr, "evaluate: %zu nao_rt runs, %d at a time\n", jobs.size(), a.jobs);
  runJobs(jobs, a.jobs);

  json summary, detail;
  std::printf("%-10s %18s %16s %18s %18s %18s %18s\n", "movement", "autonomous DTW mm", "demo NN DTW mm",
              "linear AR DTW mm", "reference RMSE mm", "blend law RMSE mm", "gain law RMSE mm");
  for (const MovementWork& w : work) {
    std::vector<double> auto_dtw, nn_dtw, ar_dtw, ref_rmse, law_rmse, gain_rmse;
    json auto_runs = json::array(), nn = json::array(), ref_runs = json::array(),
         law_runs = json::array(), gain_runs = json::array();
    for (std::size_t i = 0; i < w.auto_jobs.size(); ++i) {
      const Job& job = jobs[w.auto_jobs[i]];
      const json s = readSummary(job);
      if (numberAt(s, "ticks", job) != static_cast<double>(w.held.target[i].size()))
        throw UserError((job.dir / "summary.json").string() + ": not the rollout from " + w.held.names[i] +
                        " (another length)");
      // The hand path from s_0 against every held-out demonstration's: the nearest (the paper
      // protocol's score) and the mean.
      const HandPath path = runHandPath(arm, w.held.target[i].front(), job.dir / "ticks.csv");
      const NearestDemo nearest = nearestDemo(path, w.held.hand);
      double sum = 0.0;
      for (const HandPath& demo : w.held.hand) sum += rt::dtwMeanDistance(path, demo);
      const double d = nearest.dtw_m;
      auto_dtw.push_back(d);
      auto_runs.push_back({{"start_demo", w.held.names[i]},
                           {"run_dir", fs::relative(job.dir, out).string()},
                           {"ticks", s["ticks"]},
                           {"dtw_nearest_m", d},
                           {"nearest_demo", w.held.names[static_cast<std::size_t>(nearest.index)]},
                           {"dtw_mean_m", sum / static_cast<double>(w.held.hand.size())},
                           {"command_limited_ticks", s["faults"]["command_limited"]}});
    }
    for (std::size_t i = 0; i < w.demo_nn.size(); ++i) {
      nn_dtw.push_back(w.demo_nn[i].dtw_m);
      nn.push_back({{"demo", w.held.names[i]},
                    {"dtw_nearest_m", w.demo_nn[i].dtw_m},
                    {"nearest_demo", w.held.names[static_cast<std::size_t>(w.demo_nn[i].index)]}});
    }
    // The bar: the fit (as demonstrated, or at the canonical pace) with the lower median.
    std::size_t best_ar = 0;
    for (std::size_t k = 1; k < w.ar.size(); ++k)
      if (median(w.ar[k].dtw) < median(w.ar[best_ar].dtw)) best_ar = k;
    const ArBaseline& bar = w.ar[best_ar];
    ar_dtw = bar.dtw;
    std::vector<json> ar_fits;
    for (const ArBaseline& b : w.ar) {
      json runs = json::array();
      for (std::size_t i = 0; i < b.nearest.size(); ++i)
        runs.push_back({{"start_demo", w.held.names[i]},
                        {"ticks", w.held.target[i].size()},
                        {"dtw_nearest_m", b.nearest[i].dtw_m},
                        {"nearest_demo", w.held.names[static_cast<std::size_t>(b.nearest[i].index)]},
                        {"command_limited_ticks", b.limited[i]}});
      ar_fits.push_back({{"training_demos", w.ar_train_demos}, {"joints", arJson(b.model)}, {"rollouts", runs}});
    }
    for (std::size_t k = 0; k < a.seeds.size(); ++k) {
      for (int law = 0; law < 3; ++law) {  // 0 policy, 1 blend law, 2 gain law
        const std::vector<std::size_t>& job_list = law == 0 ? w.ref_jobs : law == 1 ? w.law_jobs : w.gain_jobs;
        const Job& job = jobs[job_list[k]];
        const json s = readSummary(job);
        const double r = numberAt(s, "ee_rmse_m", job);
        (law == 0 ? ref_rmse : law == 1 ? law_rmse : gain_rmse).push_back(r);
        (law == 0 ? ref_runs : law == 1 ? law_runs : gain_runs)
            .push_back({{"seed", a.seeds[k]},
                        {"run_dir", fs::relative(job.dir, out).string()},
                        {"reference", s["reference"]},
                        {"ticks", s["ticks"]},
                        {"ee_rmse_m", r},
                        {"ee_rmse_ticks", s["ee_rmse_ticks"]}});
      }
    }
    json m;
    m["autonomous_dtw_m"] = numberOrNull(median(auto_dtw));
    m["demo_nn_dtw_m"] = numberOrNull(median(nn_dtw));
    m["linear_ar_dtw_m"] = numberOrNull(median(ar_dtw));
    m["reference_rmse_m"] = numberOrNull(median(ref_rmse));
    m["blend_law_rmse_m"] = numberOrNull(median(law_rmse));
    m["gain_law_rmse_m"] = numberOrNull(median(gain_rmse));
    m["autonomous_runs"] = auto_dtw.size();
    m["heldout_demos"] = w.held.names.size();
    m["autonomous_dtw_per_run_m"] = auto_dtw;
    m["demo_nn_dtw_per_demo_m"] = nn_dtw;
    m["linear_ar_dtw_per_run_m"] = ar_dtw;
    m["seeds"] = a.seeds;
    m["reference_rmse_per_seed_m"] = ref_rmse;
    m["blend_law_rmse_per_seed_m"] = law_rmse;
    m["gain_law_rmse_per_seed_m"] = gain_rmse;
    m["linear_ar_orders"] = json::array();
    for (const LinearArJoint& j : bar.model.joints) m["linear_ar_orders"].push_back(j.order);
    if (w.ar.size() > 1) {
      m["linear_ar_fit"] = bar.paced ? "canonical_pace" : "as_demonstrated";
      m["linear_ar_as_demonstrated_dtw_m"] = numberOrNull(median(w.ar[0].dtw));
      m["linear_ar_canonical_pace_dtw_m"] = numberOrNull(median(w.ar[1].dtw));
    }
    summary[w.name] = m;

    json d;
    d["heldout_demos"] = w.held.names;
    d["synth_seed"] = w.held.seed;
    d["synth_seed_assumed"] = w.held.seed_assumed;
    d["autonomous"] = auto_runs;
    d["demo_nn"] = nn;
    d["linear_ar"] = ar_fits[0];
    if (ar_fits.size() > 1) d["linear_ar_canonical_pace"] = ar_fits[1];
    d["reference"] = ref_runs;
    d["blend_law"] = law_runs;
    d["gain_law"] = gain_runs;
    detail[w.name] = d;
    std::printf("%-10s %18s %16s %18s %18s %18s %18s\n", w.name.c_str(), millimetres(median(auto_dtw)).c_str(),
                millimetres(median(nn_dtw)).c_str(), millimetres(median(ar_dtw)).c_str(),
                millimetres(median(ref_rmse)).c_str(), millimetres(median(law_rmse)).c_str(),
                millimetres(median(gain_rmse)).c_str());
  }
  summary["evaluation"] = {
      {"format", "nao-rt evaluate 1"},
      {"units", "m"},
      {"autonomous_model", {{"path", a.autonomous_model}, {"checksum", "0x" + hex64(auto_model.checksum)}}},
      {"reference_model", {{"path", a.reference_model}, {"checksum", "0x" + hex64(ref_model.checksum)}}},
      {"demo_set", a.test_seed >= 0 ? json{{"kind", "test"},
                                            {"test_seed", a.test_seed},
                                            {"synth_seed", tools::kReferenceSeedBase + static_cast<std::uint64_t>(a.test_seed)},
                                            {"per_movement", a.test_demos}}
                                      : json{{"kind", "validation"}}},
      {"linear_ar_training_data", data_source},
      {"linear_ar_max_order", a.max_order},
      {"blend_law_pole", pole},
      {"gain_law", gain},
      {"detail", "detail.json"}};
  const std::string text = summary.dump(2) + "\n", detail_text = detail.dump(2) + "\n";
  for (const auto& [file, body] : {std::pair{out / "summary.json", &text}, std::pair{out / "detail.json", &detail_text}}) {
    std::ofstream f(file, std::ios::binary | std::ios::trunc);
    f << *body;
    f.close();
    if (!f) throw UserError("cannot write " + file.string());
  }
  std::printf("evaluate: wrote %s and %s; autonomous run directories in %s/<movement>/autonomous/\n",
              (out / "summary.json").string().c_str(), (out / "detail.json").string().c_str(), a.out.c_str());
}

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "evaluate",
      "Issue 13's scores per movement, in metres, into OUT/summary.json (details: OUT/detail.json;\n"
      "docs/evaluate.md): autonomous_dtw_m (nao_rt rollouts of the autonomous model from the s_0 of\n"
      "every held-out demonstration, median DTW to the nearest held-out demonstration), demo_nn_dtw_m\n"
      "(median nearest-neighbour DTW among the held-out demonstrations), linear_ar_dtw_m (the best\n"
      "per-joint linear AR model of the training split, rolled out the same way), reference_rmse_m and\n"
      "blend_law_rmse_m (nao_rt in reference mode per --seeds, policy and blend law; median).\n"
      "Runs nao_rt as a separate process per run; the run directories stay in OUT/<movement>/.");
  auto args = std::make_shared<Args>();
  cmd->add_option("--autonomous-model", args->autonomous_model, "Autonomous-mode model.bin")->capture_default_str();
  cmd->add_option("--reference-model", args->reference_model, "Reference-conditioned model.bin")->capture_default_str();
  cmd->add_option("--data", args->data,
                  "The autonomous model's data set (nao_toolchain cluster output; its fingerprint must match the\n"
                  "model's) for the linear AR fit, or 'regenerate' (its training demonstrations regenerated;\n"
                  "also the fallback when the default is missing)")
      ->capture_default_str()
      ->each([args](const std::string&) { args->data_given = true; });
  cmd->add_option("--out", args->out, "Output directory")->capture_default_str();
  cmd->add_option("--urdf", args->urdf, "Robot description")->capture_default_str()->check(CLI::ExistingFile);
  cmd->add_option("--nao-rt", args->nao_rt, "nao_rt executable (default: the one beside nao_toolchain)");
  cmd->add_option("--movement", args->movement, "whole_arm, elbow, wrist or all")
      ->check(CLI::IsMember({"whole_arm", "elbow", "wrist", "all"}))
      ->capture_default_str();
  cmd->add_option("--seeds", args->seeds, "Run seeds of the reference-mode runs")->delimiter(',')->capture_default_str();
  cmd->add_option("--jobs", args->jobs, "nao_rt processes at a time")->check(CLI::Range(1, 64))->capture_default_str();
  cmd->add_option("--max-order", args->max_order, "Largest linear AR order tried (orders 1..N, chosen per joint)")
      ->check(CLI::Range(1, kMaxLinearArOrder))
      ->capture_default_str();
  cmd->add_option("--test-seed", args->test_seed,
                  "Score on a test set instead of the model's validation demonstrations: --test-demos\n"
                  "demonstrations per movement of synthesiser run seed 1000000 + S, which neither training\n"
                  "nor model selection saw (the AR order is still chosen on the validation demonstrations)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--test-demos", args->test_demos, "Test demonstrations per movement with --test-seed")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--min-demos", args->min_demos, "Fewest held-out demonstrations per movement accepted")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->callback([args] { evaluate(*args); });
}

}  // namespace

NAO_REGISTER_COMMAND(evaluate, setup)

}  // namespace nao::tools
