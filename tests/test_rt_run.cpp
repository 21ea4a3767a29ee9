// nao_rt runs in process (rt_config, rt_run, rt_rundir, rt_cli): the run directory's contract,
// determinism, the autonomous starts, and the one-line errors for bad inputs. The policy is a
// small random model written to a temporary model.bin and loaded with --weights, so the run is
// compiled with SmallPolicyDims. References are recorded skeleton CSVs of held-out synthetic
// demonstrations (support/reference_files.hpp).
#include "rt_cli.hpp"
#include "rt_run.hpp"

#include "nao/model_file.hpp"
#include "nao/policy_kernels.hpp"
#include "nao/controller.hpp"
#include "nao/tools/baseline_laws.hpp"
#include "nao/tools/reference_source.hpp"
#include "support/random_policy.hpp"
#include "support/reference_files.hpp"
#include "support/rt_run_suite.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

using namespace nao;
using namespace nao::test::rt_suite;

namespace {

const std::string& referenceModel() {
  static const std::string path = writeModel("reference.bin", Conditioning::kReference);
  return path;
}

/// --reference file: of held-out demonstration 0 of run seed 1000000 + seed of `movement`.
rt::RunOptions recorded(const std::string& weights, const std::string& movement, const fs::path& log = {},
                        std::uint64_t seed = 1) {
  rt::RunOptions o = options(weights, "file:" + test::syntheticReferenceCsv(movement, seed, suiteDir() / "references"), log);
  o.movement = movement;
  return o;
}

}  // namespace

TEST_CASE("ticks.csv's header is exactly the contract's columns, in order") {
  const std::string expected =
      "tick,t_s,q_ref_0,q_ref_1,q_ref_2,q_ref_3,q_ref_4,r_0,r_1,r_2,r_3,r_4,a_0,a_1,a_2,a_3,a_4,"
      "q_cmd_0,q_cmd_1,q_cmd_2,q_cmd_3,q_cmd_4,q_0,q_1,q_2,q_3,q_4,ee_x,ee_y,ee_z,ee_ref_x,ee_ref_y,ee_ref_z,"
      "att_0,att_1,att_2,att_3,att_4,fault,tick_us,retarget_us,policy_us,sim_us,attm_0,attm_1,attm_2,attm_3,attm_4";
  CHECK(rt::ticksCsvHeader() == expected);
}

TEST_CASE("the weight storage of a --weights model holds its tensors 64-byte aligned, each padded to 64 bytes with zeros") {
  PolicyArch chunked = smallArch();
  chunked.chunk = 4;
  for (const PolicyArch& arch : {smallArch(), chunked}) {
    CAPTURE(arch.chunk);
    const ModelFile model = readModelFile(writeModel("storage_" + std::to_string(arch.chunk) + ".bin",
                                                     Conditioning::kReference, "{}", arch));
    std::size_t padded = 0;
    for (const TensorSpec& t : policyManifest(arch)) padded += (t.count() + 15) / 16 * 16;
    rt::WeightStorage storage;
    const std::vector<const float*> p = rt::copyWeightFile(model, storage);
    CHECK(storage.n_floats == padded);
    REQUIRE(p.size() == model.tensors.size());
    std::size_t at = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      const std::size_t n = model.tensors[i].spec.count(), n_pad = (n + 15) / 16 * 16;
      CHECK(reinterpret_cast<std::uintptr_t>(p[i]) % kModelAlignment == 0);
      CHECK(p[i] == storage.floats.get() + at);
      CHECK(std::memcmp(p[i], model.data(i), n * sizeof(float)) == 0);
      for (std::size_t k = n; k < n_pad; ++k) CHECK(p[i][k] == 0.0f);
      at += n_pad;
    }
    // The storage binds as the model (views by name, the head's sizes from the header).
    const PolicyWeights<Dims> w = bindPolicyWeights<Dims>(p.data(), p.size(), model.header.arch, model.header.conditioning);
    CHECK(w.chunk == arch.chunk);
  }
}

TEST_CASE("a run writes ticks.csv, attention.bin and summary.json as the contract says") {
  const fs::path dir = tempDir("contract");
  const Outcome r = run(recorded(referenceModel(), "elbow", dir));
  REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  CHECK(r.err.empty());

  // ticks.csv: the header, one row per tick, as many fields as columns.
  std::ifstream csv(dir / "ticks.csv");
  std::string line;
  REQUIRE(std::getline(csv, line));
  CHECK(line == rt::ticksCsvHeader());
  const auto columns = std::count(line.begin(), line.end(), ',') + 1;
  std::int64_t rows = 0;
  while (std::getline(csv, line)) {
    CHECK(std::count(line.begin(), line.end(), ',') + 1 == columns);
    ++rows;
  }
  CHECK(rows == r.report.ticks);
  CHECK(r.report.ticks > 50);

  // summary.json: the required keys.
  const nlohmann::json s = nlohmann::json::parse(bytes(dir / "summary.json"));
  CHECK(s["ticks"] == r.report.ticks);
  CHECK(s["overruns"] == 0);
  for (const char* name : kControllerFaultNames) CHECK(s["faults"].contains(name));
  CHECK(s["allocations_after_activate"].is_null());  // no probe in this suite
  for (const char* k : {"tick_us", "policy_us", "retarget_us", "sim_us"}) {
    CHECK(s[k]["p50"].is_number());
    CHECK(s[k]["p99"] >= s[k]["p50"]);
    CHECK(s[k]["max"] >= s[k]["p99"]);
  }
  CHECK(s["ee_rmse_m"].is_number());
  CHECK(s["model"]["path"] == referenceModel());
  CHECK(s["model"]["checksum"].get<std::string>().size() == 18);
  CHECK(s["reference"] == "file:" + (suiteDir() / "references" / "elbow_1.csv").string());
  CHECK(s["start_q"].size() == 5);
  CHECK(s["movement"] == "elbow");
  CHECK(s["realtime"] == false);
  CHECK(s["attention"]["records_written"] == r.report.ticks);
  MESSAGE("random small policy on a recorded elbow: ee RMSE " << r.report.ee_rmse_m * 1e3 << " mm over "
                                                             << r.report.ticks << " ticks");

  // attention.bin: the header says what it holds.
  const std::string att = bytes(dir / "attention.bin");
  REQUIRE(att.size() >= 96);
  CHECK(att.compare(0, 8, "NAOATTN1") == 0);
  std::uint64_t count = 0, payload = 0;
  std::memcpy(&count, att.data() + 16, 8);
  std::memcpy(&payload, att.data() + 32, 8);
  CHECK(count == static_cast<std::uint64_t>(std::min<std::int64_t>(r.report.ticks, kDefaultAttentionCapacity)));
  CHECK(payload == sizeof(rt::RunPayload<Dims>));
  CHECK(att.size() == 96 + count * payload);

  // The printed summary says where the files went.
  CHECK(r.out.find("ee RMSE") != std::string::npos);
  CHECK(r.out.find((dir / "summary.json").string()) != std::string::npos);
}

TEST_CASE("two runs with the same arguments give byte-identical ticks.csv (--zero-timing) and attention.bin") {
  const fs::path a = tempDir("det_a"), b = tempDir("det_b");
  for (const fs::path& dir : {a, b}) {
    rt::RunOptions o = recorded(referenceModel(), "wrist", dir, 3);
    o.zero_timing = true;
    o.ticks = 150;  // past the reference's end too (no human: hold, then home)
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  }
  const std::string csv_a = bytes(a / "ticks.csv");
  CHECK(csv_a.size() > 10000);
  CHECK(csv_a == bytes(b / "ticks.csv"));
  CHECK(bytes(a / "attention.bin") == bytes(b / "attention.bin"));
  // --zero-timing zeroes exactly the four *_us columns (before the five attm_* columns).
  std::istringstream rows(csv_a);
  std::string line;
  std::getline(rows, line);
  std::getline(rows, line);
  std::vector<std::string> cells;
  std::stringstream cs(line);
  for (std::string c; std::getline(cs, c, ',');) cells.push_back(c);
  REQUIRE(cells.size() > 10);
  for (std::size_t k = cells.size() - 9; k < cells.size() - 5; ++k) CHECK(cells[k] == "0");
}

TEST_CASE("--policy-kernel binds the weights with the kernel named, records it, and every kernel gives the same bits") {
  std::string ticks, attention;
  for (const char* kernel : {"sse", "avx2", "avx512"}) {
    PolicyKernel k{};
    REQUIRE(parsePolicyKernel(kernel, k));
    if (!policyKernelSupported(k)) continue;  // this CPU lacks it: refused (below for avx512)
    const fs::path dir = tempDir(std::string("kernel_") + kernel);
    rt::RunOptions o = recorded(referenceModel(), "elbow", dir);
    o.policy_kernel = kernel;
    o.zero_timing = true;
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
    CHECK(nlohmann::json::parse(bytes(dir / "summary.json"))["model"]["kernel"] == kernel);
    if (ticks.empty()) {
      ticks = bytes(dir / "ticks.csv");
      attention = bytes(dir / "attention.bin");
    } else {
      CHECK(bytes(dir / "ticks.csv") == ticks);
      CHECK(bytes(dir / "attention.bin") == attention);
    }
  }
  CHECK(!ticks.empty());
  CHECK_THROWS_AS(rt::runPolicyKernel("neon"), std::invalid_argument);
  if (!policyKernelSupported(PolicyKernel::kAvx512)) CHECK_THROWS(rt::runPolicyKernel("avx512"));
}

TEST_CASE("--precision int8 runs the int8 kernels, records it, stays near fp32 and is deterministic; fp32-packed is fp32") {
  // (Dims: the small test model; the committed paper model's closed-loop figures are in
  // bench/results/int8.txt.)
  std::string ticks[4];
  double rmse[4] = {0, 0, 0, 0};
  int i = 0;
  for (const char* precision : {"fp32", "int8", "int8", "fp32-packed"}) {
    const fs::path dir = tempDir(std::string("precision_") + std::to_string(i));
    rt::RunOptions o = recorded(referenceModel(), "elbow", dir);
    o.precision = precision;
    o.zero_timing = true;
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
    const nlohmann::json s = nlohmann::json::parse(bytes(dir / "summary.json"));
    CHECK(s["model"]["precision"] == precision);
    CHECK(s["model"]["kernel"] == policyKernelName(bestPolicyKernel()));
    ticks[i] = bytes(dir / "ticks.csv");
    rmse[i] = r.report.ee_rmse_m;
    ++i;
  }
  CHECK(ticks[1] == ticks[2]);  // int8 is as deterministic as fp32
  CHECK(ticks[0] != ticks[1]);  // and really ran (other bits)
  CHECK(std::fabs(rmse[1] - rmse[0]) < 0.5e-3);
  CHECK(ticks[3] == ticks[0]);  // the packed copy: the same floats, the same bits
  // Default for --weights: fp32.
  const fs::path dir = tempDir("precision_default");
  REQUIRE(run(recorded(referenceModel(), "elbow", dir)).report.status == 0);
  CHECK(nlohmann::json::parse(bytes(dir / "summary.json"))["model"]["precision"] == "fp32");
}

TEST_CASE("without --zero-timing the timing columns hold the measured stage times") {
  const fs::path dir = tempDir("timing");
  rt::RunOptions o = recorded(referenceModel(), "elbow", dir);
  o.ticks = 5;
  REQUIRE(run(o).report.status == 0);
  std::istringstream rows(bytes(dir / "ticks.csv"));
  std::string line;
  std::getline(rows, line);
  std::getline(rows, line);
  std::vector<std::string> cells;
  std::stringstream cs(line);
  for (std::string c; std::getline(cs, c, ',');) cells.push_back(c);
  REQUIRE(cells.size() > 10);
  bool measured = false;  // tick_us .. sim_us, before the five attm_* columns
  for (std::size_t k = cells.size() - 9; k < cells.size() - 5; ++k) measured = measured || cells[k] != "0";
  CHECK(measured);
}

TEST_CASE("bad inputs end the run with a non-zero status and one clear line") {
  const std::string good = referenceModel();
  const std::string data = bytes(good);
  const fs::path dir = suiteDir();
  auto variant = [&](const std::string& name, std::string content) {
    const std::string path = (dir / name).string();
    std::ofstream(path, std::ios::binary) << content;
    return path;
  };
  std::string flipped = data;
  flipped[data.size() / 2] = static_cast<char>(flipped[data.size() / 2] ^ 0x10);
  PolicyArch other = smallArch();
  other.d_model = 16;

  struct Case {
    const char* what;
    rt::RunOptions o;
    int status;
    const char* says;
  };
  std::vector<Case> cases;
  cases.push_back({"truncated weights", recorded(variant("truncated.bin", data.substr(0, data.size() / 2)), "elbow"),
                   1, "truncated"});
  cases.push_back({"a flipped byte", recorded(variant("flipped.bin", flipped), "elbow"), 1, "checksum"});
  cases.push_back({"weights of another architecture",
                   recorded(writeModel("other.bin", Conditioning::kReference, "{}", other), "elbow"), 1,
                   "differs from the compiled one"});
  cases.push_back({"a missing weights file", recorded((dir / "missing.bin").string(), "elbow"), 1, "missing.bin"});
  {
    rt::RunOptions o = recorded(good, "elbow");
    o.urdf_path = (dir / "missing.urdf").string();
    cases.push_back({"a missing URDF", o, 1, "missing.urdf"});
  }
  cases.push_back({"an unknown reference", options(good, "camera:0"), 2, "unknown reference 'camera:0'"});
  {
    rt::RunOptions o = options(good, "synthetic:elbow");
    o.movement = "elbow";
    cases.push_back({"a synthetic reference (the runtime never synthesises one)", o, 2,
                     "unknown reference 'synthetic:elbow'"});
  }
  cases.push_back({"no reference", options(good, ""), 2, "--reference is required"});
  {
    rt::RunOptions o = recorded(good, "elbow");
    o.movement = "wave";
    cases.push_back({"a movement the model does not have", o, 1, "no movement 'wave'"});
  }
  {
    rt::RunOptions o = options(good, "file:/nonexistent/skeleton.csv");
    o.movement = "elbow";
    cases.push_back({"a missing reference file", o, 1, "skeleton.csv"});
  }
  cases.push_back({"file: without --movement", options(good, "file:/nonexistent/skeleton.csv"), 2, "--movement"});
  {
    rt::RunOptions o = options(good, "none");
    o.movement = "elbow";
    cases.push_back({"none with a reference-conditioned model", o, 1, "autonomous"});
  }
  cases.push_back({"no model at all", recorded("", "elbow"), 1, "--weights"});
  {
    const std::string blocker = variant("not_a_dir", "x");
    cases.push_back({"a run directory that cannot be made", recorded(good, "elbow", fs::path(blocker) / "run"),
                     1, "run directory"});
  }
  for (const Case& c : cases) {
    const std::string what = c.what;
    CAPTURE(what);
    int status = 0;
    const std::string err = errorLine(c.o, status);
    CHECK(status == c.status);
    CHECK(oneLine(err));
    CHECK(err.rfind("nao_rt: ", 0) == 0);
    CHECK_MESSAGE(err.find(c.says) != std::string::npos, "expected '" << std::string(c.says) << "' in: " << err);
  }
}

TEST_CASE("the command line: --help exits 0, a bad flag or value exits 2 with one line") {
  auto parse = [](std::vector<const char*> args, rt::CommandLine& cl, std::string& out, std::string& err) {
    args.insert(args.begin(), "nao_rt");
    std::ostringstream o, e;
    const int status = rt::parseCommandLine(static_cast<int>(args.size()), args.data(), cl, o, e);
    out = o.str();
    err = e.str();
    return status;
  };
  rt::CommandLine cl;
  std::string out, err;
  CHECK(parse({"--help"}, cl, out, err) == 0);
  for (const char* flag : {"--weights", "--urdf", "--reference", "--movement", "--start", "--start-pose", "--ticks", "--seconds",
                           "--realtime", "--log", "--attention-shm", "--info", "--zero-timing", "--precision",
                           "--lola-io-thread", "--lola-io-wait-ms"})
    CHECK_MESSAGE(out.find(flag) != std::string::npos, flag);

  for (std::vector<const char*> bad : {std::vector<const char*>{"--bogus"}, {"--ticks", "-3"}, {"--ticks", "ten"},
                                       {"--ticks", "5", "--seconds", "2"}, {"--seed", "1"}, {"--start-demo", "0"},
                                       {"--test-seed", "1"}, {"--start", "-1"}, {"--start-pose", "0,1,2"},
                                       {"--precision", "fp16"},
                                       {"--emulate-tick-ms", "30"}, {"--lola-io-wait-ms", "12"}}) {
    rt::CommandLine c;
    CAPTURE(bad[0]);
    CHECK(parse(bad, c, out, err) == 2);
    CHECK(oneLine(err));
    CHECK(err.rfind("nao_rt: ", 0) == 0);
  }

  rt::CommandLine c;
  REQUIRE(parse({"--weights", "m.bin", "--reference", "file:x.csv", "--movement", "elbow", "--ticks",
                 "20", "--realtime", "--log", "out", "--attention-shm", "nao_x", "--zero-timing", "--precision", "int8"},
                c, out, err) == -1);
  CHECK(c.run.weights_path == "m.bin");
  CHECK(c.run.reference == "file:x.csv");
  CHECK(c.run.movement == "elbow");
  CHECK(c.run.start_index == -1);
  CHECK(c.run.start_pose.empty());
  CHECK(c.run.ticks == 20);
  CHECK(c.run.realtime);
  CHECK(c.run.log_dir == "out");
  CHECK(c.run.attention_shm == "nao_x");
  CHECK(c.run.zero_timing);
  CHECK(c.run.precision == "int8");
  CHECK_FALSE(c.info);
  CHECK(c.run.lola.io_thread == (NAO_LOLA_IO_THREAD_DEFAULT != 0));

  rt::CommandLine l;
  REQUIRE(parse({"--robot", "lola:/tmp/x.sock", "--lola-io-thread", "--lola-io-wait-ms", "2.5"}, l, out, err) == -1);
  CHECK(l.run.lola.io_thread);
  CHECK(l.run.lola.io_wait_ms == doctest::Approx(2.5));
  rt::CommandLine one;
  REQUIRE(parse({"--robot", "lola", "--lola-one-thread"}, one, out, err) == -1);
  CHECK_FALSE(one.run.lola.io_thread);
}

TEST_CASE("--realtime paces the ticks on 100 ms deadlines and gives the same records as back to back") {
  const fs::path a = tempDir("rt_a"), b = tempDir("rt_b");
  rt::RunOptions o = recorded(referenceModel(), "elbow", a);
  o.ticks = 5;
  o.zero_timing = true;
  o.realtime = true;
  std::ostringstream out, err;
  const auto t0 = std::chrono::steady_clock::now();
  const rt::RunReport r = rt::runController<Dims>(o, out, err);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  REQUIRE_MESSAGE(r.status == 0, r.error);
  // At most one warning line (SCHED_FIFO / mlockall not permitted).
  CHECK((err.str().empty() || oneLine(err.str())));
  const nlohmann::json j = nlohmann::json::parse(r.summary_json);
  CHECK(j["realtime"] == true);
  CHECK(j["realtime_scheduling"].is_string());
  CHECK(j["skipped_periods"].is_number());
  // Five ticks on the grid: the last starts 400 ms after the first.
  CHECK(s > 0.39);
  if (r.overruns == 0) {
    o.realtime = false;
    o.log_dir = b.string();
    REQUIRE(run(o).report.status == 0);
    CHECK(bytes(a / "ticks.csv") == bytes(b / "ticks.csv"));
  }
}

TEST_CASE("--attention-shm puts the ring into shared memory for the run") {
  rt::RunOptions o = recorded(referenceModel(), "elbow");
  o.ticks = 3;
  o.attention_shm = "nao_rt_test_run_" + std::to_string(::getpid());
  const Outcome r = run(o);
  REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  const nlohmann::json j = nlohmann::json::parse(r.report.summary_json);
  CHECK(j["attention"]["shm"] == o.attention_shm);
  CHECK(j["attention"]["records_written"] == 3);
  // Unlinked at the end of the run.
  CHECK_FALSE(fs::exists("/dev/shm/" + o.attention_shm));
  rt::RunOptions bad = o;
  bad.attention_shm = "a/b";
  int status = 0;
  CHECK(oneLine(errorLine(bad, status)));
  CHECK(status == 1);
}

namespace {

// Starts of a test model: elbow has two, whole_arm one, wrist none.
const JointVector kStartA = (JointVector() << 1.2, -0.3, 1.0, 0.6, 0.1).finished();
const JointVector kStartB = (JointVector() << 0.9, -0.5, 0.8, 0.9, -0.2).finished();
const JointVector kStartC = (JointVector() << 1.4, -0.2, 1.2, 0.5, 0.0).finished();

// The model's movements are elbow, whole_arm, wrist (writeModel): starts in that order.
std::string startsMetadata(const std::string& metadata = "{}") {
  const ModelStarts starts = {{{"elbow_003", 40, kStartA}, {"elbow_010", 25, kStartB}},
                              {{"whole_arm_001", 30, kStartC}},
                              {}};
  return withModelStarts(metadata, {"elbow", "whole_arm", "wrist"}, starts);
}

const std::string& autonomousModel() {
  static const std::string path = writeModel("autonomous.bin", Conditioning::kAutonomous, startsMetadata());
  return path;
}

rt::RunOptions rollout(const std::string& movement, const fs::path& log = {}) {
  rt::RunOptions o = options(autonomousModel(), "none", log);
  o.movement = movement;
  o.zero_timing = true;
  return o;
}

}  // namespace

TEST_CASE("--reference none rolls an autonomous model out from its I-th start of the movement, at rest, for that start's length") {
  const fs::path d0 = tempDir("start_0"), d1 = tempDir("start_1");
  const Outcome r0 = run(rollout("elbow", d0));  // --start absent: start 0
  REQUIRE_MESSAGE(r0.report.status == 0, r0.report.error);
  rt::RunOptions o1 = rollout("elbow", d1);
  o1.start_index = 1;
  const Outcome r1 = run(o1);
  REQUIRE_MESSAGE(r1.report.status == 0, r1.report.error);

  const nlohmann::json s0 = nlohmann::json::parse(bytes(d0 / "summary.json"));
  const nlohmann::json s1 = nlohmann::json::parse(bytes(d1 / "summary.json"));
  CHECK(r0.report.ticks == 40);
  CHECK(r1.report.ticks == 25);
  CHECK(s0["start_name"] == "elbow_003");
  CHECK(s0["start_index"] == 0);
  CHECK(s1["start_name"] == "elbow_010");
  CHECK(s1["start_index"] == 1);
  for (int j = 0; j < kNumJoints; ++j) {
    CHECK(s0["start_q"][static_cast<std::size_t>(j)].get<double>() == kStartA[j]);
    CHECK(s1["start_q"][static_cast<std::size_t>(j)].get<double>() == kStartB[j]);
  }
  CHECK(s0["ee_rmse_m"].is_null());  // nothing to be scored against: no recorded reference
  CHECK(s0["faults"]["no_human"] == 0);  // an autonomous model needs no human
  CHECK(r0.out.find("elbow_003") != std::string::npos);
  CHECK(bytes(d0 / "ticks.csv") != bytes(d1 / "ticks.csv"));

  // The start is a pose at rest with a(-1) = 0: --start-pose of the same pose for the same
  // length is the same run, byte for byte.
  const fs::path dp = tempDir("start_pose_a");
  rt::RunOptions pose = rollout("elbow", dp);
  pose.start_pose.assign(kStartA.data(), kStartA.data() + kNumJoints);
  pose.ticks = 40;
  const Outcome rp = run(pose);
  REQUIRE_MESSAGE(rp.report.status == 0, rp.report.error);
  CHECK(bytes(dp / "ticks.csv") == bytes(d0 / "ticks.csv"));
  const nlohmann::json sp = nlohmann::json::parse(bytes(dp / "summary.json"));
  CHECK(sp["start_name"].is_null());
  CHECK(sp["start_index"].is_null());
  CHECK(sp["start_q"] == s0["start_q"]);

  // Without --ticks, --start-pose runs the mean length of the movement's starts: (40 + 25) / 2.
  rt::RunOptions mean = rollout("elbow");
  mean.start_pose.assign(kStartB.data(), kStartB.data() + kNumJoints);
  const Outcome rm = run(mean);
  REQUIRE_MESSAGE(rm.report.status == 0, rm.report.error);
  CHECK(rm.report.ticks == 33);

  // A movement with its own single start.
  const Outcome rw = run(rollout("whole_arm"));
  REQUIRE_MESSAGE(rw.report.status == 0, rw.report.error);
  CHECK(rw.report.ticks == 30);
}

TEST_CASE("--reference none without a usable start, or --start/--start-pose without it, is refused with one line") {
  struct Case {
    const char* what;
    rt::RunOptions o;
    int status;
    const char* says;
  };
  std::vector<Case> cases;
  {
    rt::RunOptions o = rollout("elbow");
    o.start_index = 2;
    cases.push_back({"a start past the movement's last", o, 2, "(0..1)"});
  }
  cases.push_back({"a movement without starts", rollout("wrist"), 2, "--start-pose"});
  {
    rt::RunOptions o = rollout("wrist");
    o.start_pose = {1.0, -0.2, 1.0, 0.5, 0.0};
    cases.push_back({"--start-pose of a movement without starts, without --ticks", o, 2, "--ticks"});
  }
  {
    rt::RunOptions o = options(writeModel("autonomous_nostarts.bin", Conditioning::kAutonomous), "none");
    o.movement = "elbow";
    cases.push_back({"a model without starts", o, 2, "model-starts"});
  }
  {
    rt::RunOptions o = options(writeModel("autonomous_badstarts.bin", Conditioning::kAutonomous,
                                          R"({"starts":{"elbow":[{"name":"e","ticks":0,"q":[0,0,0,0,0]}],"whole_arm":[],"wrist":[]}})"),
                               "none");
    o.movement = "elbow";
    cases.push_back({"unusable starts", o, 1, "\"starts\""});
  }
  {
    rt::RunOptions o = rollout("elbow");
    o.start_index = 0;
    o.start_pose = {1.0, -0.2, 1.0, 0.5, 0.0};
    cases.push_back({"--start with --start-pose", o, 2, "exclude"});
  }
  {
    rt::RunOptions o = rollout("elbow");
    o.start_pose = {1.0, -0.2, std::nan(""), 0.5, 0.0};
    cases.push_back({"a non-finite --start-pose", o, 2, "finite"});
  }
  {
    rt::RunOptions o = rollout("elbow");
    o.start_pose = {1.0, -0.2, 1.0};
    cases.push_back({"a --start-pose of 3 angles", o, 2, "--start-pose needs 5"});
  }
  {
    rt::RunOptions o = recorded(referenceModel(), "elbow");
    o.start_index = 0;
    cases.push_back({"--start with a recorded reference", o, 2, "--start needs --reference none"});
  }
  {
    rt::RunOptions o = recorded(referenceModel(), "elbow");
    o.start_pose = {1.0, -0.2, 1.0, 0.5, 0.0};
    cases.push_back({"--start-pose with a recorded reference", o, 2, "--start-pose needs --reference none"});
  }
  {
    rt::RunOptions o = options(referenceModel(), "none");
    o.movement = "elbow";
    cases.push_back({"none with a reference-conditioned model", o, 1, "autonomous"});
  }
  for (const Case& c : cases) {
    const std::string what = c.what;
    CAPTURE(what);
    int status = 0;
    const std::string err = errorLine(c.o, status);
    CHECK(status == c.status);
    CHECK(oneLine(err));
    CHECK_MESSAGE(err.find(c.says) != std::string::npos, "expected '" << std::string(c.says) << "' in: " << err);
  }

  rt::CommandLine cl;
  std::ostringstream out, err;
  const char* argv[] = {"nao_rt", "--reference", "none", "--movement", "elbow", "--start-pose", "0.1,-0.2,0.3,0.4,-0.5"};
  REQUIRE(rt::parseCommandLine(7, argv, cl, out, err) == -1);
  CHECK(cl.run.start_pose == std::vector<double>{0.1, -0.2, 0.3, 0.4, -0.5});
  const char* argv2[] = {"nao_rt", "--start", "4"};
  rt::CommandLine cl2;
  REQUIRE(rt::parseCommandLine(3, argv2, cl2, out, err) == -1);
  CHECK(cl2.run.start_index == 4);
}

TEST_CASE("an autonomous model may run against a reference, which then only serves for evaluation") {
  rt::RunOptions o = recorded(writeModel("autonomous_ref.bin", Conditioning::kAutonomous), "whole_arm");
  o.ticks = 40;
  const Outcome r = run(o);
  REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  CHECK(std::isfinite(r.report.ee_rmse_m));
  CHECK(r.report.faults[0] == 0);  // no_human: the reference is not an input
}

TEST_CASE("an action law replaces the policy in the run and is named in summary.json; nao_rt has no flag for one") {
  for (const char* flag : {"--blend-law-pole", "--gain-law"}) {
    rt::CommandLine cl;
    std::ostringstream out, err;
    const char* argv[] = {"nao_rt", flag, "0.7"};
    CHECK_MESSAGE(rt::parseCommandLine(3, argv, cl, out, err) == 2, flag << ": expected an unknown flag");
  }
  const fs::path dir = tempDir("blend_law");
  rt::RunOptions o = recorded(referenceModel(), "elbow", dir);
  o.ticks = 30;
  tools::BlendLaw blend(0.7);
  const Outcome r = run(o, &blend);
  REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  const nlohmann::json s = nlohmann::json::parse(bytes(dir / "summary.json"));
  CHECK(s["action_law"] == "blend law");
  CHECK(s["policy_ticks"] == 0);
  // The policy's run: no such key.
  rt::RunOptions policy = recorded(referenceModel(), "elbow", tempDir("blend_law_policy"));
  policy.ticks = 30;
  REQUIRE(run(policy).report.status == 0);
  CHECK_FALSE(nlohmann::json::parse(bytes(fs::path(policy.log_dir) / "summary.json")).contains("action_law"));
}


TEST_CASE("the gain law drives the arm by a = G (clamp(f) - q) on the feature target, recomputed here from the snapped key poses") {
  const double gain = 1.0894;
  const fs::path dir = tempDir("gain_law");
  rt::RunOptions o = recorded(referenceModel(), "elbow", dir);
  o.ticks = 60;
  tools::GainLaw law(gain);
  const Outcome r = run(o, &law);
  REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
  CHECK(nlohmann::json::parse(bytes(dir / "summary.json"))["action_law"] == "gain law");

  // f: the online blend toward the snapped key pose r (pole 0.7), started at rest on r(0); the
  // action is G times its distance, clamped to the limits, from the angles the tick started at.
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const auto t = test::readCsvColumns(dir / "ticks.csv");
  REQUIRE(t.at("tick").size() == 60u);
  const double pole = kFeatureBlendPole;
  JointVector f, v = JointVector::Zero(), q_start;
  for (int j = 0; j < kNumJoints; ++j) {
    f[j] = t.at("r_" + std::to_string(j))[0];
    q_start[j] = t.at("q_cmd_" + std::to_string(j))[0] - t.at("a_" + std::to_string(j))[0];
  }
  double worst = 0.0, largest = 0.0;
  int checked = 0;
  for (std::size_t i = 0; i < 60; ++i) {
    JointVector rr, q_prev, a;
    for (int j = 0; j < kNumJoints; ++j) {
      const std::string s = std::to_string(j);
      rr[j] = t.at("r_" + s)[i];
      q_prev[j] = i == 0 ? q_start[j] : t.at("q_" + s)[i - 1];
      a[j] = t.at("a_" + s)[i];
    }
    v = pole * pole * v + (1.0 - pole) * (1.0 - pole) * (rr - f);
    f += v;
    const JointVector expected = gain * (clampToLimits(arm, f) - q_prev);
    worst = std::max(worst, (a - expected).cwiseAbs().maxCoeff());
    largest = std::max(largest, a.cwiseAbs().maxCoeff());
    ++checked;
  }
  MESSAGE(checked << " ticks: worst |a - G (f - q)| " << worst << " rad");
  // ticks.csv prints 17 significant digits; q_start is recovered as q_cmd - a (two roundings).
  CHECK(worst < 1e-9);
  CHECK(largest > 1e-3);  // the arm moved: the comparison is not of zeros
}

TEST_CASE("a reference model's law.gain is added by nao_rt: the first action is the net's plus gain times the policy's r") {
  // Three files that differ in law.gain alone (0, 1.5, 3). The run starts on the reference's
  // first pose, so r = 0 at tick 0 and the three first actions are equal; at tick 1 the state
  // and the policy's inputs are then the same, so a(g) = net + g·r gives a(3) − a(0) =
  // 2 (a(1.5) − a(0)) to float rounding, whatever r is.
  std::vector<JointVector> first;
  std::vector<double> zero;  // tick 0's actions, joint-major per run
  std::vector<double> share, action_sq;  // summary.json's network_share; Σ|a|² over the 2 ticks
  for (const float gain : {0.0f, 1.5f, 3.0f}) {
    const std::string model =
        writeModel("law_" + std::to_string(static_cast<int>(2 * gain)) + ".bin", Conditioning::kReference, "{}",
                   smallArch(), 7, gain);
    const fs::path dir = tempDir("law_" + std::to_string(static_cast<int>(2 * gain)));
    rt::RunOptions o = recorded(model, "wrist", dir);
    o.ticks = 2;
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
    const auto t = test::readCsvColumns(dir / "ticks.csv");
    JointVector a, a0;
    for (int j = 0; j < kNumJoints; ++j) {
      a[j] = t.at("a_" + std::to_string(j))[1];
      a0[j] = t.at("a_" + std::to_string(j))[0];
      zero.push_back(a0[j]);
    }
    first.push_back(a);
    action_sq.push_back(a0.squaredNorm() + a.squaredNorm());
    const nlohmann::json summary = nlohmann::json::parse(bytes(dir / "summary.json"));
    REQUIRE(summary["policy_ticks"] == 2);
    share.push_back(summary["network_share"].get<double>());
  }
  const JointVector d1 = first[1] - first[0], d2 = first[2] - first[0];
  for (int j = 0; j < kNumJoints; ++j) CHECK(zero[static_cast<std::size_t>(j)] == zero[static_cast<std::size_t>(kNumJoints + j)]);
  MESSAGE("law 1.5 moves tick 1's action by " << d1.transpose() << " rad");
  CHECK(d1.cwiseAbs().minCoeff() > 1e-4);  // r is nonzero in every joint: the law acts
  CHECK((d2 - 2.0 * d1).cwiseAbs().maxCoeff() < 1e-6);
  // The network share: both ticks have the same state and inputs in the three runs, so the
  // network's part is the law-free run's action; nao_rt's figure is recomputed from that.
  CHECK(share[0] == 1.0);
  for (std::size_t k = 1; k < 3; ++k) {
    CHECK(share[k] == doctest::Approx(std::sqrt(action_sq[0] / action_sq[k])).epsilon(1e-12));
    CHECK(share[k] != 1.0);
  }
}

TEST_CASE("summary.json's network share: 1 for an autonomous model, null when an evaluation law replaces the policy") {
  const fs::path auto_dir = tempDir("share_auto");
  const Outcome a = run(rollout("elbow", auto_dir));
  REQUIRE_MESSAGE(a.report.status == 0, a.report.error);
  const nlohmann::json sa = nlohmann::json::parse(bytes(auto_dir / "summary.json"));
  CHECK(sa["policy_ticks"] == sa["ticks"]);
  CHECK(sa["network_share"].get<double>() == 1.0);  // a = the network's, bit for bit

  const fs::path law_dir = tempDir("share_law");
  rt::RunOptions o = recorded(writeModel("share_law.bin", Conditioning::kReference), "elbow", law_dir);
  o.ticks = 5;
  tools::GainLaw gain(1.0894);
  const Outcome l = run(o, &gain);
  REQUIRE_MESSAGE(l.report.status == 0, l.report.error);
  const nlohmann::json sl = nlohmann::json::parse(bytes(law_dir / "summary.json"));
  CHECK(sl["policy_ticks"] == 0);
  CHECK(sl["network_share"].is_null());
}

TEST_CASE("the online reference is the offline one: nao_rt retargets with the demonstration's calibrated human scale, so the key poses it snaps and the feature target it blends are the trajectory it is scored against") {
  // A noisy two-camera stream (dropouts, bridged ticks): with a per-frame scale the snaps
  // flickered differently from the offline labels and the controller tracked another target
  // (up to 37 mm away on whole_arm seed 3).
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const ModelFile model = readModelFile(referenceModel());
  for (const std::string movement : {"whole_arm", "wrist"}) {
    CAPTURE(movement);
    const fs::path dir = tempDir("online_offline_" + movement);
    // The recorded skeleton of the same frames makeSyntheticReference prepares in memory.
    rt::RunOptions o = recorded(referenceModel(), movement, dir, 3);
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
    const auto& names = model.header.movement_names;
    const int m = static_cast<int>(std::find(names.begin(), names.end(), movement) - names.begin());
    const tools::ReferenceStream ref = tools::makeSyntheticReference(
        arm, tools::parseMovement(movement), 3, 0, modelKeyPoses(model, m), RetargetParams{});
    const auto t = test::readCsvColumns(dir / "ticks.csv");
    const std::size_t n = t.at("tick").size();
    REQUIRE(n + 1 >= ref.target.size());
    // f recomputed from the snapped key poses the controller logged (r), as in the gain-law test.
    const double pole = kFeatureBlendPole;
    JointVector f = JointVector::Zero(), v = JointVector::Zero();
    double worst_f = 0.0, worst_q = 0.0;
    int measured = 0;
    for (std::size_t i = 0; i + 1 < ref.target.size(); ++i) {
      JointVector rr, q_ref;
      for (int j = 0; j < kNumJoints; ++j) {
        rr[j] = t.at("r_" + std::to_string(j))[i];
        q_ref[j] = t.at("q_ref_" + std::to_string(j))[i];
      }
      if (i == 0) f = rr;
      v = pole * pole * v + (1.0 - pole) * (1.0 - pole) * (rr - f);
      f += v;
      worst_f = std::max(worst_f, (f - ref.target[i + 1]).cwiseAbs().maxCoeff());
      if (ref.measured[i]) {
        worst_q = std::max(worst_q, (q_ref - ref.retargeted[i]).cwiseAbs().maxCoeff());
        ++measured;
      }
    }
    MESSAGE(movement << ": " << measured << " measured ticks, worst |q_ref online - offline| " << worst_q
                     << " rad, worst |f online - offline| " << worst_f << " rad");
    CHECK(measured > 50);
    // The same solver on the same frames (measured 4e-8 rad apart: the LM's stopping tolerance,
    // reached from another float path); the snaps, and so f, agree exactly (measured 2e-16).
    CHECK(worst_q < 1e-6);
    CHECK(worst_f < 1e-9);
  }
}

TEST_CASE("an autonomous model with a chunk of 5 runs in nao_rt, deterministically, and summary.json records its head") {
  PolicyArch arch = smallArch();
  arch.chunk = 5;
  const std::string model = writeModel("autonomous_chunk.bin", Conditioning::kAutonomous, startsMetadata(), arch, 9);
  std::vector<std::string> ticks;
  for (const char* name : {"chunk_a", "chunk_b"}) {
    const fs::path dir = tempDir(name);
    rt::RunOptions o = options(model, "none", dir);
    o.movement = "elbow";
    o.ticks = 20;
    o.zero_timing = true;
    const Outcome r = run(o);
    REQUIRE_MESSAGE(r.report.status == 0, r.report.error);
    CHECK(r.report.ticks == 20);
    const nlohmann::json s = nlohmann::json::parse(bytes(dir / "summary.json"));
    CHECK(s["model"]["chunk"] == 5);
    CHECK_FALSE(s["model"].contains("bins"));
    CHECK(s["faults"]["policy_nonfinite"] == 0);
    ticks.push_back(bytes(dir / "ticks.csv"));
  }
  CHECK(ticks[0] == ticks[1]);
  // The arm moves under the ensembled chunks' actions (not a held pose).
  const auto t = test::readCsvColumns(suiteDir() / "chunk_a" / "ticks.csv");
  const std::vector<double>& q1 = t.at("q_cmd_1");
  CHECK(*std::max_element(q1.begin(), q1.end()) - *std::min_element(q1.begin(), q1.end()) > 1e-4);
}
