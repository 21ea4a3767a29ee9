// nao_rt's live reference, --reference openpose:DIR0,DIR1 (docs/nao_rt.md "Live reference").
//
// End to end through the built binaries: a synthetic recording (tests/live/make_fixture.sh) is
// replayed by `nao_toolchain replay` into camera folders that do not exist when nao_rt starts,
// and run live with exactly the contract's command
//   nao_rt --reference openpose:DIR0,DIR1 --calibration FILE --movement whole_arm --realtime
//          --seconds S --log RUN
// (plus --weights when the build has no compiled-in model); the same recording triangulated
// offline (nao_toolchain triangulate) runs through --reference file:. Then a hostile replay
// (NAO_REPLAY_FAULTS). In process: the command-line errors of the live reference, and a live run
// that never sees a frame.
#include "nao/metrics.hpp"
#include "rt_run.hpp"

#include "nao/calibration_json.hpp"
#include "nao/kinematics.hpp"
#include "nao/model_file.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <thread>

extern char** environ;

using namespace nao;
namespace fs = std::filesystem;

namespace {

using Columns = std::map<std::string, std::vector<double>>;

const fs::path kFixture = NAO_RT_LIVE_FIXTURE;
constexpr std::uint32_t kNoHuman = 1u << 0, kHumanTimeout = 1u << 1, kHumanBridged = 1u << 14;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / ("rt_live_" + std::to_string(::getpid())) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

/// Starts argv with stdout and stderr into `log` and `env` added to the environment.
pid_t spawn(const std::vector<std::string>& argv, const fs::path& log, const std::vector<std::string>& env = {}) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::vector<std::string> env_text(env);
  for (char** e = environ; *e != nullptr; ++e) env_text.emplace_back(*e);
  std::vector<char*> envp;
  for (std::string& e : env_text) envp.push_back(e.data());
  envp.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  REQUIRE_MESSAGE(rc == 0, "cannot start " << argv[0]);
  return pid;
}

/// The exit status of `pid`, or -1 (killed) if it runs longer than timeout_s.
int waitExit(pid_t pid, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (std::chrono::steady_clock::now() > end) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

/// Waits until `log` holds `text` (nao_rt prints its plan right before the loop starts).
bool waitForText(const fs::path& log, const std::string& text, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (test::readFile(log.string()).find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

nlohmann::json readJson(const fs::path& path) { return nlohmann::json::parse(test::readFile(path.string())); }

/// nao_rt's model arguments: the fixture's model, or none for the compiled-in one.
std::vector<std::string> modelArgs() {
  if (fs::exists(kFixture / "model.bin")) return {"--weights", (kFixture / "model.bin").string()};
  return {};
}

fs::path recording() { return kFixture / "recording" / "whole_arm_000"; }

int recordingFrames() {
  int n = 0;
  for (const fs::directory_entry& e : fs::directory_iterator(recording() / "cam0"))
    n += e.path().extension() == ".json" ? 1 : 0;
  return n;
}

void requireFixture() {
  REQUIRE_MESSAGE(fs::exists(kFixture / "complete"),
                  "no fixture in " << kFixture.string() << " (the CTest fixture rt_live_fixture makes it)");
}

/// The live run: nao_rt started on folders that do not exist, then the replay into them.
struct LiveRun {
  fs::path dir, run;
  int rt_status = -1, replay_status = -1;
  double seconds = 0.0;
};

LiveRun runLive(const std::string& name, const std::string& faults) {
  LiveRun r;
  r.dir = freshDir(name);
  r.run = r.dir / "run";
  const std::string cam0 = (r.dir / "rig" / "cam0").string(), cam1 = (r.dir / "rig" / "cam1").string();
  REQUIRE(!fs::exists(r.dir / "rig"));
  // The recording, then 3 s with nobody: the run ends on its own, after the replay.
  r.seconds = std::ceil(recordingFrames() / 30.0 + 3.0);
  std::vector<std::string> rt = {NAO_RT_EXE};
  for (const std::string& a : modelArgs()) rt.push_back(a);
  for (const std::string& a :
       {std::string("--reference"), "openpose:" + cam0 + "," + cam1, std::string("--calibration"),
        (recording() / "calibration.json").string(), std::string("--movement"), std::string("whole_arm"),
        std::string("--realtime"), std::string("--seconds"), std::to_string(static_cast<int>(r.seconds)),
        std::string("--log"), r.run.string()})
    rt.push_back(a);
  const pid_t rt_pid = spawn(rt, r.dir / "nao_rt.log");
  if (!waitForText(r.dir / "nao_rt.log", "nao_rt: openpose:", 60.0)) {
    kill(rt_pid, SIGKILL);
    waitExit(rt_pid, 5.0);
    FAIL("nao_rt did not start its loop: " << test::readFile((r.dir / "nao_rt.log").string()));
  }
  std::vector<std::string> env;
  if (!faults.empty()) env.push_back("NAO_REPLAY_FAULTS=" + faults);
  const pid_t replay_pid =
      spawn({NAO_TOOLCHAIN_EXE, "replay", "--recording", recording().string(), "--to", cam0 + "," + cam1},
            r.dir / "replay.log", env);
  r.replay_status = waitExit(replay_pid, r.seconds + 30.0);
  r.rt_status = waitExit(rt_pid, r.seconds + 60.0);
  MESSAGE(test::readFile((r.dir / "nao_rt.log").string()));
  return r;
}

/// The recording through --reference file: (its offline triangulation), back to back.
fs::path runFile(const std::string& name) {
  const fs::path dir = freshDir(name);
  std::vector<std::string> rt = {NAO_RT_EXE};
  for (const std::string& a : modelArgs()) rt.push_back(a);
  for (const std::string& a : {std::string("--reference"), "file:" + (kFixture / "skeleton.csv").string(),
                               std::string("--movement"), std::string("whole_arm"), std::string("--log"),
                               (dir / "run").string()})
    rt.push_back(a);
  const int status = waitExit(spawn(rt, dir / "nao_rt.log"), 120.0);
  REQUIRE_MESSAGE(status == 0, test::readFile((dir / "nao_rt.log").string()));
  return dir / "run";
}

std::uint32_t faultOf(const Columns& c, std::size_t t) { return static_cast<std::uint32_t>(c.at("fault")[t]); }
bool humanSeen(const Columns& c, std::size_t t) { return (faultOf(c, t) & (kNoHuman | kHumanBridged)) == 0; }

/// The hand path (ee) from the first to the last tick with a human.
std::vector<Eigen::Vector3d> humanSpanPath(const Columns& c) {
  const std::size_t n = c.at("tick").size();
  std::size_t first = n, last = 0;
  for (std::size_t t = 0; t < n; ++t)
    if (humanSeen(c, t)) first = std::min(first, t), last = t;
  std::vector<Eigen::Vector3d> path;
  for (std::size_t t = first; t <= last && t < n; ++t)
    path.emplace_back(c.at("ee_x")[t], c.at("ee_y")[t], c.at("ee_z")[t]);
  return path;
}

JointVector qAt(const Columns& c, const char* prefix, std::size_t t) {
  JointVector q;
  for (int j = 0; j < kNumJoints; ++j) q[j] = c.at(prefix + std::to_string(j))[t];
  return q;
}

/// Largest distance of a path's points from their mean, m.
double spread(const std::vector<Eigen::Vector3d>& path) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : path) mean += p;
  mean /= static_cast<double>(std::max<std::size_t>(path.size(), 1));
  double d = 0.0;
  for (const Eigen::Vector3d& p : path) d = std::max(d, (p - mean).norm());
  return d;
}

void checkRealTime(const nlohmann::json& s) {
  const auto ticks = s["ticks"].get<std::int64_t>();
#if NAO_RT_COUNTS_ALLOCATIONS
  REQUIRE_MESSAGE(!s["allocations_after_activate"].is_null(), "this build's nao_rt counts allocations");
  CHECK(s["allocations_after_activate"] == 0);
  // The reader thread parses and triangulates: it allocates, counted on its own.
  CHECK(s["camera"]["reader_allocations"].get<std::int64_t>() > 0);
#endif
  CHECK_MESSAGE(s["overruns"].get<std::int64_t>() * 100 <= ticks,
                s["overruns"] << " overruns in " << ticks << " ticks (at most 1 %)");
}

// A small reference-conditioned model for the in-process runs.
std::string smallModel(const fs::path& dir) {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  ModelHeader h;
  h.arch = smallArch();
  h.joints = trainedJoints(arm);
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = "{}";
  const std::string path = (dir / "model.bin").string();
  writeModelFile(path, h, test::makeRandomPolicy(h.arch, arm, 5).tensors);
  return path;
}

rt::RunReport runInProcess(const rt::RunOptions& o, std::string* err_text = nullptr) {
  std::ostringstream out, err;
  const rt::RunReport r = rt::runController<SmallPolicyDims>(o, out, err);
  if (err_text != nullptr) *err_text = err.str();
  return r;
}

}  // namespace

TEST_CASE("a recording replayed live into camera folders moves the arm as the same recording through file: does") {
  requireFixture();
  const LiveRun live = runLive("clean", "");
  REQUIRE(live.replay_status == 0);
  REQUIRE(live.rt_status == 0);
  const fs::path file_run = runFile("clean_file");

  const nlohmann::json s = readJson(live.run / "summary.json");
  checkRealTime(s);
  const nlohmann::json& cam = s["camera"];
  const int n_frames = recordingFrames();
  // Every frame file appeared after the source started: each read once, none malformed.
  CHECK(cam["files_parsed"] == 2 * n_frames);
  CHECK(cam["files_malformed"] == 0);
  CHECK(cam["frames_complete"].get<int>() + cam["frames_incomplete"].get<int>() + cam["frames_skipped"].get<int>() ==
        n_frames);
  CHECK(cam["takes"] == s["ticks"]);
  CHECK(cam["latency_ms"]["n"].get<int>() > 0);
  CHECK(cam["human_scale_m"].get<double>() > 0.3);  // fixed within the recording's first seconds

  const Columns lc = test::readCsvColumns(live.run / "ticks.csv");
  const Columns fc = test::readCsvColumns(file_run / "ticks.csv");
  REQUIRE(lc.count("q_4"));
  std::size_t live_human = 0, file_human = 0;
  for (std::size_t t = 0; t < lc.at("tick").size(); ++t) live_human += humanSeen(lc, t) ? 1 : 0;
  for (std::size_t t = 0; t < fc.at("tick").size(); ++t) file_human += humanSeen(fc, t) ? 1 : 0;
  // The live run sees the human about as many ticks as the recording has (the first frames
  // after its start, and within a tick or two of the end).
  CHECK(live_human + 5 >= file_human);

  const std::vector<Eigen::Vector3d> live_path = humanSpanPath(lc), file_path = humanSpanPath(fc);
  const double dtw = rt::dtwMeanDistance(live_path, file_path);
  MESSAGE("hand path DTW live vs file: " << dtw * 1e3 << " mm (" << live_path.size() << " / " << file_path.size()
                                         << " ticks; the path spans " << spread(file_path) * 1e3 << " mm)");
  // The arm draws a circle of several cm: agreeing within 15 mm is not the trivial outcome.
  CHECK(spread(file_path) > 0.05);
  CHECK(dtw <= 0.015);
}

TEST_CASE("a hostile replay is counted, never fatal, and the arm is held safely while nobody is seen") {
  requireFixture();
  // Truncated frames, frames with nobody, camera 0's folder gone for a second, then camera 0
  // stopping for good (with two cameras nothing triangulates after that: the hold, then the
  // return home).
  const double stop_at = std::floor(recordingFrames() / 30.0) - 3.0;
  const LiveRun live = runLive("hostile", "truncate_every=9,no_person_every=20,remove_folder_at=3,remove_for=1,stop_at=" +
                                              std::to_string(static_cast<int>(stop_at)));
  REQUIRE(live.replay_status == 0);
  REQUIRE(live.rt_status == 0);
  const nlohmann::json s = readJson(live.run / "summary.json");
  checkRealTime(s);
  const nlohmann::json& cam = s["camera"];
  CHECK(cam["files_malformed"].get<int>() > 0);
  CHECK(cam["folder_gone"].get<int>() >= 1);
  CHECK(cam["folder_back"].get<int>() >= 1);
  CHECK(cam["frames_no_person"].get<int>() > 0);
  CHECK(cam["camera_stopped"].get<int>() >= 1);
  CHECK(s["faults"]["no_human"].get<int>() > 0);
  CHECK(s["faults"]["human_timeout"].get<int>() > 0);

  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const Columns c = test::readCsvColumns(live.run / "ticks.csv");
  const std::size_t n = c.at("tick").size();
  REQUIRE(n == s["ticks"].get<std::size_t>());
  const double period = s["period_s"].get<double>();
  const JointVector home = clampToLimits(arm, (JointVector() << 1.40, -0.20, 1.20, 0.50, 0.00).finished());
  int n_hold = 0, n_home = 0;
  for (std::size_t t = 1; t < n; ++t) {
    const JointVector q = qAt(c, "q_", t), q_prev = qAt(c, "q_", t - 1);
    for (int j = 0; j < kNumJoints; ++j) {
      // Never outside the arm's limits, never faster than its joints go.
      CHECK(q[j] >= arm.q_min[j] - 1e-3);
      CHECK(q[j] <= arm.q_max[j] + 1e-3);
      CHECK(std::abs(q[j] - q_prev[j]) <= arm.v_max[j] * period * 1.05 + 1e-6);
    }
    const std::uint32_t f = faultOf(c, t);
    if ((f & (kNoHuman | kHumanBridged)) && !(f & kHumanTimeout)) {
      // Nobody seen: the reference is held exactly as it was.
      ++n_hold;
      CHECK(qAt(c, "q_ref_", t) == qAt(c, "q_ref_", t - 1));
      CHECK(qAt(c, "r_", t) == qAt(c, "r_", t - 1));
    }
    if (f & kHumanTimeout) {
      // Nobody for longer than the timeout: every joint's action points home.
      ++n_home;
      const JointVector a = qAt(c, "a_", t);
      for (int j = 0; j < kNumJoints; ++j) CHECK(a[j] * (home[j] - q_prev[j]) >= 0.0);
    }
  }
  MESSAGE(n_hold << " ticks held without a human, " << n_home << " returning home");
  CHECK(n_hold >= 10);
  REQUIRE(n_home >= 2);
  // Returning home: closer at the end of the run than when the timeout began.
  std::size_t first_home = n;
  for (std::size_t t = 0; t < n; ++t)
    if (faultOf(c, t) & kHumanTimeout) first_home = std::min(first_home, t);
  CHECK((qAt(c, "q_", n - 1) - home).norm() < (qAt(c, "q_", first_home - 1) - home).norm());
}

TEST_CASE("openpose: command-line problems are usage errors named in one line, before anything runs") {
  const fs::path dir = freshDir("usage");
  const std::string calibration = std::string(NAO_TEST_DATA_DIR) + "/triangulate/calibration.json";
  struct Case {
    std::string reference, calibration, expect;
    double fps = 0.0, human_scale = 0.0, seconds = 2.0;
  };
  const std::string a = (dir / "a").string(), b = (dir / "b").string();
  const std::vector<Case> cases = {
      {"openpose:" + a, calibration, "at least 2 cameras"},
      {"openpose:" + a + ",", calibration, "folder 1 is empty"},
      {"openpose:" + a + "," + a, calibration, "is given for two cameras"},
      {"openpose:" + a + "," + b, "", "needs --calibration"},
      {"openpose:" + a + "," + b + "," + (dir / "c").string(), calibration, "has 2 cameras but"},
      {"openpose:" + a + "," + b, calibration, "no length of its own", 0.0, 0.0, 0.0},
      {"openpose:" + a + "," + b, calibration, "--human-scale 60", 0.0, 60.0},
      {"file:" + a, "", "--fps needs --reference openpose", 30.0},
      {"none", calibration, "--calibration needs --reference openpose"},
  };
  for (const Case& k : cases) {
    CAPTURE(k.reference);
    rt::RunOptions o;
    o.reference = k.reference;
    o.movement = "whole_arm";
    o.calibration_path = k.calibration;
    o.fps = k.fps;
    o.human_scale_m = k.human_scale;
    o.seconds = k.seconds;
    const rt::RunReport r = runInProcess(o);
    CHECK(r.status == 2);
    CHECK_MESSAGE(r.error.find(k.expect) != std::string::npos, r.error);
    CHECK(r.error.find('\n') == std::string::npos);
  }
  // A calibration that does not parse: a file problem (exit 1) naming the file.
  rt::RunOptions o;
  o.reference = "openpose:" + a + "," + b;
  o.movement = "whole_arm";
  o.calibration_path = test::writeTempFile("rt_live_bad_calibration.json", "{\"cameras\": [");
  o.seconds = 1.0;
  const rt::RunReport r = runInProcess(o);
  CHECK(r.status == 1);
  CHECK_MESSAGE(r.error.find("rt_live_bad_calibration.json") != std::string::npos, r.error);
  CHECK(!fs::exists(a));  // nothing watched, nothing made
}

TEST_CASE("a live run that never sees a frame ends normally after --seconds, every tick no human") {
  const fs::path dir = freshDir("no_frame");
  rt::RunOptions o;
  o.weights_path = smallModel(dir);
  o.reference = "openpose:" + (dir / "rig" / "cam0").string() + "," + (dir / "rig" / "cam1").string();
  o.calibration_path = std::string(NAO_TEST_DATA_DIR) + "/triangulate/calibration.json";
  o.movement = "whole_arm";
  o.seconds = 4.0;
  o.log_dir = (dir / "run").string();
  const rt::RunReport r = runInProcess(o);
  REQUIRE_MESSAGE(r.status == 0, r.error);
  CHECK(r.ticks == 40);
  CHECK(r.faults[0] == 40);  // no_human
  CHECK(r.faults[1] > 0);    // human_timeout after 3 s: the arm goes home (it starts there)
  const nlohmann::json s = nlohmann::json::parse(r.summary_json);
  CHECK(s["camera"]["takes"] == 40);
  CHECK(s["camera"]["takes_no_human"] == 40);
  CHECK(s["camera"]["files_parsed"] == 0);
  CHECK(s["camera"]["latency_ms"]["n"] == 0);
  CHECK(s["ee_rmse_m"].is_null());  // no target to score against
  CHECK(s["reference"].get<std::string>().rfind("openpose:", 0) == 0);
  // The arm started at home and stayed there.
  const Columns c = test::readCsvColumns(dir / "run" / "ticks.csv");
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const JointVector home = clampToLimits(arm, rt::RunOptions{}.controller.home);
  CHECK((qAt(c, "q_", 39) - home).norm() < 1e-3);
}
