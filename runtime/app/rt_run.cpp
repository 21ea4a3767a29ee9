// The parts of a nao_rt run that do not depend on the policy's compiled dimensions
// (rt_run.hpp): configure-time preparation and the output after the loop.
#include "rt_run.hpp"

#include "nao/policy_kernels.hpp"
#include "nao/tools/synth.hpp"

#include <nlohmann/json.hpp>

#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>

namespace nao::rt {
namespace {

namespace fs = std::filesystem;

constexpr const char* kReferenceHelp = "synthetic:whole_arm|elbow|wrist, file:PATH or none";
// Longest run: one hour of ticks (NAO's battery lasts about that). The run buffers are sized
// by it before the loop, so a larger count would only allocate until the machine gives up.
constexpr std::int64_t kMaxRunTicks = 36000;
constexpr const char* kMaxRunText = "36000 ticks (1 h at 10 Hz)";

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

bool isSynthMovement(const std::string& name) {
  for (const char* m : tools::kMovementNames)
    if (name == m) return true;
  return false;
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

std::string hex64(std::uint64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// The model: --weights FILE or the compiled-in bytes, checked like start-up must check it.
void loadModel(const RunOptions& o, const PolicyArch& compiled_arch, PreparedRun& p) {
  std::string origin;
  if (!o.weights_path.empty()) {
    p.model_source = o.weights_path;
    origin = o.weights_path;
    p.model = readModelFile(o.weights_path);
  } else if (o.compiled.bytes != nullptr) {
    // In place: the header and offsets are the generated constants, the checksum is verified
    // once over the bytes in .rodata; nothing is decoded or copied (docs/policy.md, codegen).
    p.model_source = "compiled-in";
    origin = "compiled-in model";
    p.model = mappedModelFile(o.compiled, origin);
    p.model_bytes = o.compiled.bytes;
    p.model_offsets = o.compiled.offsets;
  } else {
    throw std::runtime_error(
        "no model is compiled into this build (models/default.bin did not exist when it was built); pass "
        "--weights FILE, or train one with toolchain/nao train and rebuild");
  }
  // Precision: asked for, or what the compiled-in model was generated with (fp32 for --weights).
  p.precision = runPrecision(o.precision, p.model_bytes != nullptr, o.compiled);
  // A compiled-in int8 or packed copy replaces the image's matrices: now that the checksum has
  // been verified over the image, its pages leave the resident set before the copy's own check
  // (checked once, like the model's bytes) brings that in; the run faults back the few it still
  // reads (docs/embedded.md, RSS).
  if (p.model_bytes != nullptr && p.precision == WeightPrecision::kInt8 && o.compiled.int8_bytes != nullptr) {
    releaseImagePages(o.compiled.bytes, o.compiled.size);
    checkInt8Image(o.compiled, p.model.header.arch, origin);
    p.int8_bytes = o.compiled.int8_bytes;
  } else if (p.model_bytes != nullptr && p.precision == WeightPrecision::kFp32Packed &&
             o.compiled.packed_bytes != nullptr) {
    releaseImagePages(o.compiled.bytes, o.compiled.size);
    checkPackedImage(o.compiled, p.model.header.arch, origin);
    p.packed_bytes = o.compiled.packed_bytes;
  }
  try {
    checkJointsMatch(p.model, p.arm, origin);
  } catch (const ModelFileError& e) {
    throw ModelFileError(std::string(e.what()) + " (" + o.urdf_path + ")");
  }
  try {
    nao::detail::requireArch(compiled_arch, p.model.header.arch);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(origin + ": " + e.what() + "; nao_rt runs only models of its compiled architecture");
  }
}

void appendNumber(std::string& s, double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

void appendNumber(std::string& s, float v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

template <class Int>
void appendInt(std::string& s, Int v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

nlohmann::ordered_json statsJson(const LatencyStats& s) {
  return {{"p50", s.p50}, {"p99", s.p99}, {"max", s.max}};
}

// NaN has no JSON spelling: null.
nlohmann::ordered_json numberOrNull(double v) {
  return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

void writeText(const fs::path& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error("cannot write " + path.string());
  f.write(text.data(), static_cast<std::streamsize>(text.size()));
  f.close();
  if (!f) throw std::runtime_error("error while writing " + path.string());
}

std::string millis(double us) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f ms", us * 1e-3);
  return buf;
}

}  // namespace

std::string oneLine(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  return s;
}

ReferenceSpec parseReferenceSpec(const std::string& reference, const std::string& movement) {
  ReferenceSpec s;
  if (reference == "none") {
    s.kind = ReferenceKind::kNone;
    if (movement.empty())
      throw UsageError("--reference none needs --movement M (the movement to roll out: whole_arm, elbow or wrist)");
    s.movement = movement;
  } else if (startsWith(reference, "synthetic:")) {
    s.kind = ReferenceKind::kSynthetic;
    s.movement = reference.substr(10);
    if (!isSynthMovement(s.movement))
      throw UsageError("unknown synthetic movement '" + s.movement + "' in --reference " + reference +
                       " (synthetic:whole_arm, synthetic:elbow or synthetic:wrist)");
    if (!movement.empty() && movement != s.movement)
      throw UsageError("--movement " + movement + " contradicts --reference " + reference);
  } else if (startsWith(reference, "file:")) {
    s.kind = ReferenceKind::kFile;
    s.path = reference.substr(5);
    if (s.path.empty()) throw UsageError("--reference file: needs a path (file:PATH)");
    if (movement.empty()) throw UsageError("--reference " + reference + " needs --movement M (the movement it shows)");
    s.movement = movement;
  } else {
    throw UsageError("unknown reference '" + reference + "' (" + kReferenceHelp + ")");
  }
  return s;
}

ValidationSet validationDemos(const std::string& metadata_json, const std::string& movement,
                              const std::string& origin) {
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  const nlohmann::json* val = nullptr;
  if (j.is_object() && j.contains("split") && j["split"].is_object() && j["split"].contains("val") &&
      j["split"]["val"].is_array())
    val = &j["split"]["val"];
  if (val == nullptr)
    throw std::runtime_error(origin + ": the model's metadata names no validation demonstrations (split.val); "
                                      "--reference none needs them to start and to be evaluated");
  ValidationSet v;
  // The trainer records its own seed, not the synthesiser's; the data set of toolchain/nao
  // train is synthesised with seed 1. A future data.synth_seed is honoured.
  if (j.contains("data") && j["data"].is_object() && j["data"].contains("synth_seed") &&
      j["data"]["synth_seed"].is_number_unsigned()) {
    v.seed = j["data"]["synth_seed"].get<std::uint64_t>();
    v.seed_assumed = false;
  }
  for (const nlohmann::json& n : *val) {
    if (!n.is_string()) continue;
    const std::string name = n.get<std::string>();
    const auto cut = name.rfind('_');
    if (cut == std::string::npos || name.substr(0, cut) != movement) continue;
    const std::string digits = name.substr(cut + 1);
    int index = 0;
    const auto r = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    if (digits.empty() || r.ec != std::errc() || r.ptr != digits.data() + digits.size() || index < 0) continue;
    v.names.push_back(name);
    v.indices.push_back(index);
  }
  if (v.names.empty())
    throw std::runtime_error(origin + ": the model's metadata names no validation demonstration of movement '" +
                             movement + "' (split.val)");
  return v;
}

ValidationSet testDemos(const std::string& movement, std::uint64_t test_seed, int count) {
  if (count < 1) throw std::invalid_argument("a test set needs at least one demonstration");
  ValidationSet v;
  v.seed = tools::kReferenceSeedBase + test_seed;
  v.seed_assumed = false;
  for (int i = 0; i < count; ++i) {
    char index[16];
    std::snprintf(index, sizeof index, "%03d", i);
    v.names.push_back(movement + "_test" + std::to_string(test_seed) + "_" + index);
    v.indices.push_back(i);
  }
  return v;
}

std::int64_t modelPhaseTicks(const std::string& metadata_json, const std::string& origin) {
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("training") || !j["training"].is_object() || !j["training"].contains("phase_ticks"))
    return 0;
  const nlohmann::json& v = j["training"]["phase_ticks"];
  if (!v.is_number_integer() || v.get<std::int64_t>() < 1 || v.get<std::int64_t>() > 100000)
    throw std::runtime_error(origin + ": the model's metadata has an unusable training.phase_ticks (an integer in [1, 100000])");
  return v.get<std::int64_t>();
}

RetargetParams modelRetargetSetting(const std::string& metadata_json, const RetargetParams& defaults,
                                    const std::string& origin) {
  RetargetParams r = defaults;
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("data") || !j["data"].is_object() || !j["data"].contains("retarget") ||
      j["data"]["retarget"].is_null())
    return r;  // a model that does not say: the default (hand priority)
  const nlohmann::json& s = j["data"]["retarget"];
  const std::string bad = origin + ": the model's metadata has an unusable data.retarget ";
  if (!s.is_object() || !s.contains("priority") || !s["priority"].is_string() ||
      !parseRetargetPriority(s["priority"].get<std::string>().c_str(), r.priority))
    throw std::runtime_error(bad + "(priority must be \"hand\" or \"joints\")");
  if (s.contains("lambda_q")) {
    if (!s["lambda_q"].is_number() || !(s["lambda_q"].get<double>() >= 0.0) || !std::isfinite(s["lambda_q"].get<double>()))
      throw std::runtime_error(bad + "(lambda_q must be a finite number >= 0)");
    r.lambda_q = s["lambda_q"].get<double>();
  }
  if (s.contains("posture_weights")) {
    const nlohmann::json& w = s["posture_weights"];
    if (!w.is_array() || w.size() != static_cast<std::size_t>(kNumJoints))
      throw std::runtime_error(bad + "(posture_weights must hold " + std::to_string(kNumJoints) + " numbers)");
    for (int k = 0; k < kNumJoints; ++k) {
      const nlohmann::json& x = w[static_cast<std::size_t>(k)];
      if (!x.is_number() || !(x.get<double>() > 0.0) || !std::isfinite(x.get<double>()))
        throw std::runtime_error(bad + "(posture_weights must be finite and > 0)");
      r.posture_weights[k] = x.get<double>();
    }
  }
  return r;
}

PreparedRun prepareRun(const RunOptions& o, const PolicyArch& compiled_arch) {
  PreparedRun p;
  p.spec = parseReferenceSpec(o.reference, o.movement);
  if (o.test_seed >= 0 && p.spec.kind != ReferenceKind::kNone)
    throw UsageError("--test-seed needs --reference none (it replaces the validation demonstrations a rollout starts from)");
  if (o.start_demo >= 0 && p.spec.kind != ReferenceKind::kNone)
    throw UsageError("--start-demo needs --reference none (it picks the held-out demonstration to start from)");
  if (!(o.controller.blend_law_pole >= 0.0 && o.controller.blend_law_pole < 1.0))
    throw UsageError("--blend-law-pole must be in [0, 1)");
  if (!(o.controller.gain_law >= 0.0 && std::isfinite(o.controller.gain_law)))
    throw UsageError("--gain-law must be a finite gain >= 0");
  if (o.controller.gain_law > 0.0 && o.controller.blend_law_pole > 0.0)
    throw UsageError("--gain-law and --blend-law-pole exclude each other (each replaces the policy)");
  if (o.ticks < 0) throw UsageError("--ticks must be positive");
  if (o.seconds < 0.0 || !std::isfinite(o.seconds)) throw UsageError("--seconds must be positive");
  if (o.ticks > 0 && o.seconds > 0.0) throw UsageError("--ticks and --seconds exclude each other");
  if (!(o.controller.period_s > 0.0)) throw UsageError("the control period must be positive");
  // Counts in double before any cast: llround of 1e20 is undefined (it gave one tick).
  if (o.ticks > kMaxRunTicks)
    throw UsageError("--ticks " + std::to_string(o.ticks) + " is more than the longest run, " + kMaxRunText);
  if (o.seconds > 0.0 && !(o.seconds / o.controller.period_s <= static_cast<double>(kMaxRunTicks))) {
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%g", o.seconds);
    throw UsageError(std::string("--seconds ") + seconds + " is more than the longest run, " + kMaxRunText);
  }

  p.arm = loadArmModel(o.urdf_path);
  loadModel(o, compiled_arch, p);
  const ModelHeader& h = p.model.header;
  const auto it = std::find(h.movement_names.begin(), h.movement_names.end(), p.spec.movement);
  if (it == h.movement_names.end())
    throw std::runtime_error("the model (" + p.model_source + ") has no movement '" + p.spec.movement +
                             "' (it has: " + joined(h.movement_names) + ")");
  p.movement_index = static_cast<int>(it - h.movement_names.begin());
  if (p.spec.kind == ReferenceKind::kNone && h.conditioning != Conditioning::kAutonomous)
    throw std::runtime_error("--reference none needs an autonomous-mode model; " + p.model_source +
                             " is reference-conditioned (it imitates a reference: use synthetic:M or file:PATH)");
  if (o.controller.blend_law_pole > 0.0 && h.conditioning == Conditioning::kAutonomous)
    throw UsageError("--blend-law-pole replaces a reference-conditioned policy; " + p.model_source +
                     " is an autonomous-mode model (the blend law needs the snapped human key pose)");
  if (o.controller.gain_law > 0.0 && h.conditioning == Conditioning::kAutonomous)
    throw UsageError("--gain-law replaces a reference-conditioned policy; " + p.model_source +
                     " is an autonomous-mode model (the gain law needs the feature-extracted reference)");
  p.centroids = modelKeyPoses(p.model, p.movement_index);
  // The reference is retargeted the way the model's training data was.
  p.retarget = modelRetargetSetting(h.metadata_json, o.controller.retarget, p.model_source);
  p.phase_ticks = modelPhaseTicks(h.metadata_json, p.model_source);

  std::int64_t default_ticks = 0;
  switch (p.spec.kind) {
    case ReferenceKind::kSynthetic:
      p.reference = tools::makeSyntheticReference(p.arm, tools::parseMovement(p.spec.movement), o.seed, 0, p.centroids,
                                                   p.retarget);
      break;
    case ReferenceKind::kFile:
      p.reference = tools::makeFileReference(p.arm, p.spec.path, p.spec.movement, p.centroids, p.retarget);
      break;
    case ReferenceKind::kNone: {
      if (!isSynthMovement(p.spec.movement))
        throw std::runtime_error("--reference none: the validation demonstrations of '" + p.spec.movement +
                                 "' cannot be regenerated (the synthesiser draws whole_arm, elbow and wrist)");
      p.validation = o.test_seed >= 0 ? testDemos(p.spec.movement, static_cast<std::uint64_t>(o.test_seed), o.test_demos)
                                      : validationDemos(h.metadata_json, p.spec.movement, p.model_source);
      const char* set = o.test_seed >= 0 ? "test" : "validation";
      const tools::Movement m = tools::parseMovement(p.spec.movement);
      JointVector s0 = JointVector::Zero();
      double length = 0.0;
      for (int index : p.validation.indices) {
        p.validation_demos.push_back(tools::makeDemoReference(p.arm, m, p.validation.seed, index, p.centroids, p.retarget));
        s0 += p.validation_demos.back().target.front();
        length += static_cast<double>(p.validation_demos.back().target.size());
      }
      const double n = static_cast<double>(p.validation_demos.size());
      p.q_start = s0 / n;
      default_ticks = static_cast<std::int64_t>(std::lround(length / n));
      p.reference.movement = p.spec.movement;
      p.reference.description = "none (rollout from s_0, the mean start of " +
                                std::to_string(p.validation_demos.size()) + " " + set + " demonstration(s), seed " +
                                std::to_string(p.validation.seed) + ")";
      if (o.start_demo >= 0) {
        // The paper's protocol: one rollout from the s_0 of one held-out demonstration, as long as it.
        if (o.start_demo >= static_cast<int>(p.validation_demos.size()))
          throw UsageError("--start-demo " + std::to_string(o.start_demo) + ": there are " +
                           std::to_string(p.validation_demos.size()) + " " + set + " demonstration(s) of " +
                           p.spec.movement + " (0.." + std::to_string(p.validation_demos.size() - 1) + ")");
        const tools::ReferenceStream& d = p.validation_demos[static_cast<std::size_t>(o.start_demo)];
        p.q_start = d.target.front();
        default_ticks = static_cast<std::int64_t>(d.target.size());
        p.reference.description = std::string("none (rollout from s_0 of ") + set + " demonstration " +
                                  p.validation.names[static_cast<std::size_t>(o.start_demo)] + ", index " +
                                  std::to_string(o.start_demo) + " of " + std::to_string(p.validation_demos.size()) +
                                  ", seed " + std::to_string(p.validation.seed) + ")";
      }
      break;
    }
  }
  if (p.spec.kind != ReferenceKind::kNone) {
    default_ticks = static_cast<std::int64_t>(p.reference.frames.size());
    p.has_targets = !p.reference.target.empty();
    p.q_start = p.has_targets ? p.reference.target.front() : o.controller.home;
  }
  if (o.ticks > 0)
    p.ticks = o.ticks;
  else if (o.seconds > 0.0)
    p.ticks = std::max<std::int64_t>(1, std::llround(o.seconds / o.controller.period_s));
  else
    p.ticks = default_ticks;
  if (p.ticks <= 0) throw std::runtime_error("nothing to run: the reference has no ticks");
  if (p.ticks > kMaxRunTicks)
    throw std::runtime_error("the reference (" + p.reference.description + ") has " + std::to_string(p.ticks) +
                             " ticks, more than the longest run, " + kMaxRunText + ": give --ticks or --seconds");

  if (!o.log_dir.empty()) {
    std::error_code ec;
    fs::create_directories(o.log_dir, ec);
    if (ec || !fs::is_directory(o.log_dir))
      throw std::runtime_error("cannot create the run directory " + o.log_dir + (ec ? ": " + ec.message() : ""));
    if (access(o.log_dir.c_str(), W_OK) != 0)
      throw std::runtime_error("cannot write into the run directory " + o.log_dir + ": " + std::strerror(errno));
  }
  return p;
}

std::string ticksCsvHeader() {
  std::string s = "tick,t_s";
  for (const char* name : {"q_ref", "r", "a", "q_cmd", "q"})
    for (int j = 0; j < kNumJoints; ++j) s += std::string(",") + name + "_" + std::to_string(j);
  s += ",ee_x,ee_y,ee_z,ee_ref_x,ee_ref_y,ee_ref_z";
  for (int j = 0; j < kNumJoints; ++j) s += ",att_" + std::to_string(j);
  s += ",fault,tick_us,retarget_us,policy_us,sim_us";
  // Appended (the columns before keep their positions): the raw attention mass.
  for (int j = 0; j < kNumJoints; ++j) s += ",attm_" + std::to_string(j);
  return s;
}

std::string ticksCsvRow(const TickRecord& r, bool zero_timing) {
  std::string s;
  s.reserve(1024);
  appendInt(s, r.tick);
  s += ',';
  appendNumber(s, r.t_s);
  for (const JointVector* v : {&r.q_ref, &r.r, &r.a, &r.q_cmd, &r.q})
    for (int j = 0; j < kNumJoints; ++j) {
      s += ',';
      appendNumber(s, (*v)[j]);
    }
  for (const Eigen::Vector3d* p : {&r.ee, &r.ee_ref})
    for (int k = 0; k < 3; ++k) {
      s += ',';
      appendNumber(s, (*p)[k]);
    }
  for (float a : r.att) {
    s += ',';
    appendNumber(s, a);
  }
  s += ',';
  appendInt(s, r.fault);
  for (double us : {r.tick_us, r.retarget_us, r.policy_us, r.sim_us}) {
    s += ',';
    appendNumber(s, zero_timing ? 0.0 : us);
  }
  for (float a : r.attm) {
    s += ',';
    appendNumber(s, a);
  }
  return s;
}

void spinForNs(std::int64_t ns) {
  const std::int64_t end = monotonicNs() + ns;
  while (monotonicNs() < end) {
  }
}

void sleepUntilNs(std::int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / 1000000000);
  ts.tv_nsec = static_cast<long>(t_ns % 1000000000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

RealtimeScheduling enterRealtime() {
  RealtimeScheduling s;
  s.old_policy = sched_getscheduler(0);
  sched_param old{};
  sched_getparam(0, &old);
  s.old_priority = old.sched_priority;
  std::string problems;
  sched_param fifo{};
  fifo.sched_priority = std::min(50, sched_get_priority_max(SCHED_FIFO));
  if (sched_setscheduler(0, SCHED_FIFO, &fifo) == 0)
    s.fifo = true;
  else
    problems = std::string("SCHED_FIFO: ") + std::strerror(errno);
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0)
    s.locked = true;
  else
    problems += (problems.empty() ? "" : "; ") + std::string("mlockall: ") + std::strerror(errno);
  if (!problems.empty())
    s.warning = "real-time scheduling not permitted (" + problems + "); running on absolute deadlines without it";
  return s;
}

void leaveRealtime(const RealtimeScheduling& s) {
  if (s.locked) munlockall();
  if (s.fifo) {
    sched_param old{};
    old.sched_priority = s.old_priority;
    sched_setscheduler(0, s.old_policy, &old);
  }
}

RobotSpec parseRobotSpec(const std::string& robot, const std::string& default_socket) {
  RobotSpec r;
  if (robot == "ode") return r;
  if (robot == "lola") {
    r.lola = true;
    r.socket_path = default_socket;
    return r;
  }
  if (robot.rfind("lola:", 0) == 0 && robot.size() > 5) {
    r.lola = true;
    r.socket_path = robot.substr(5);
    return r;
  }
  throw UsageError("--robot '" + robot + "': expected ode, lola or lola:SOCKET");
}

void finishRun(const RunOptions& o, const PreparedRun& p, const std::vector<TickRecord>& records,
               const AttentionRingView& ring, const LoopTotals& totals, std::ostream& out, RunReport& report) {
  using nlohmann::ordered_json;
  report.ticks = static_cast<std::int64_t>(records.size());
  report.allocations_after_activate = totals.allocations;
  report.faults.fill(0);
  std::vector<double> tick_us, retarget_us, policy_us, sim_us;
  double sum_sq = 0.0;
  std::int64_t n_ref = 0, slow = 0;
  for (const TickRecord& r : records) {
    for (int b = 0; b < kNumControllerFaults; ++b)
      if (r.fault & (1u << b)) ++report.faults[static_cast<std::size_t>(b)];
    tick_us.push_back(r.tick_us);
    retarget_us.push_back(r.retarget_us);
    policy_us.push_back(r.policy_us);
    sim_us.push_back(r.sim_us);
    if (r.tick_us > o.controller.period_s * 1e6) ++slow;
    if (r.ee_ref.allFinite()) {
      sum_sq += (r.ee - r.ee_ref).squaredNorm();
      ++n_ref;
    }
  }
  report.overruns = report.faults[5];
  static_assert(kFaultOverrun == 1u << 5, "overrun is fault bit 5");
  report.ee_rmse_m = n_ref > 0 ? std::sqrt(sum_sq / static_cast<double>(n_ref)) : std::nan("");
  report.tick_us = latencyStats(tick_us);
  report.retarget_us = latencyStats(retarget_us);
  report.policy_us = latencyStats(policy_us);
  report.sim_us = latencyStats(sim_us);

  // Autonomous rollout: DTW of the hand path (from s_0) to each validation demonstration's
  // feature-extracted hand path.
  std::vector<double> dtw_per_demo;
  if (p.spec.kind == ReferenceKind::kNone) {
    ArmData kin;
    std::vector<Eigen::Vector3d> robot;
    robot.push_back(forwardKinematics(p.arm, kin, clampToLimits(p.arm, p.q_start)));
    for (const TickRecord& r : records) robot.push_back(r.ee);
    double sum = 0.0;
    for (const tools::ReferenceStream& demo : p.validation_demos) {
      std::vector<Eigen::Vector3d> path;
      for (const JointVector& q : demo.target) path.push_back(forwardKinematics(p.arm, kin, q));
      const double d = dtwMeanDistance(robot, path);
      dtw_per_demo.push_back(d);
      sum += d;
      // The nearest demonstration (the first of equals): the paper-protocol score.
      if (!(d >= report.ee_dtw_nearest_m)) {
        report.ee_dtw_nearest_m = d;
        report.ee_dtw_nearest_index = static_cast<int>(dtw_per_demo.size()) - 1;
      }
    }
    report.ee_dtw_m = sum / static_cast<double>(p.validation_demos.size());
  }

  const bool logging = !o.log_dir.empty();
  const fs::path dir(o.log_dir);
  AttentionFileSummary attention;
  attention.records_written = recordsWritten(*ring.header);
  if (logging) {
    std::string csv = ticksCsvHeader() + "\n";
    for (const TickRecord& r : records) csv += ticksCsvRow(r, o.zero_timing) + "\n";
    writeText(dir / "ticks.csv", csv);
    attention = writeAttentionFile((dir / "attention.bin").string(), ring);
  }

  ordered_json j;
  j["ticks"] = report.ticks;
  j["period_s"] = o.controller.period_s;
  j["duration_s"] = static_cast<double>(report.ticks) * o.controller.period_s;
  j["overruns"] = report.overruns;
  ordered_json faults = ordered_json::object();
  for (int b = 0; b < kNumControllerFaults; ++b)
    faults[kControllerFaultNames[static_cast<std::size_t>(b)]] = report.faults[static_cast<std::size_t>(b)];
  j["faults"] = faults;
  j["allocations_after_activate"] =
      totals.allocations >= 0 ? ordered_json(totals.allocations) : ordered_json(nullptr);
  j["tick_us"] = statsJson(report.tick_us);
  j["retarget_us"] = statsJson(report.retarget_us);
  j["policy_us"] = statsJson(report.policy_us);
  j["sim_us"] = statsJson(report.sim_us);
  j["slow_ticks"] = slow;
  j["ee_rmse_m"] = numberOrNull(report.ee_rmse_m);
  j["ee_rmse_ticks"] = n_ref;
  if (p.spec.kind == ReferenceKind::kNone) {
    j["ee_dtw_m"] = numberOrNull(report.ee_dtw_m);
    // With --test-seed the demonstrations below are the test set's (the keys keep their names).
    j["demo_set"] = o.test_seed >= 0 ? "test" : "validation";
    j["validation_demos"] = p.validation.names;
    j["validation_seed"] = p.validation.seed;
    j["validation_seed_assumed"] = p.validation.seed_assumed;
    j["ee_dtw_nearest_m"] = numberOrNull(report.ee_dtw_nearest_m);
    j["ee_dtw_nearest_demo"] = report.ee_dtw_nearest_index >= 0
                                   ? ordered_json(p.validation.names[static_cast<std::size_t>(report.ee_dtw_nearest_index)])
                                   : ordered_json(nullptr);
    j["ee_dtw_nearest_index"] =
        report.ee_dtw_nearest_index >= 0 ? ordered_json(report.ee_dtw_nearest_index) : ordered_json(nullptr);
    ordered_json per_demo = ordered_json::array();
    for (double d : dtw_per_demo) per_demo.push_back(numberOrNull(d));
    j["ee_dtw_per_demo_m"] = per_demo;
    j["start_demo"] = o.start_demo >= 0 ? ordered_json(p.validation.names[static_cast<std::size_t>(o.start_demo)])
                                        : ordered_json(nullptr);
    j["start_demo_index"] = o.start_demo >= 0 ? ordered_json(o.start_demo) : ordered_json(nullptr);
  }
  if (o.controller.blend_law_pole > 0.0) j["blend_law_pole"] = o.controller.blend_law_pole;
  if (o.controller.gain_law > 0.0) j["gain_law"] = o.controller.gain_law;
  j["model"] = {{"path", p.model_source},
                {"checksum", hex64(p.model.checksum)},
                {"conditioning", conditioningName(p.model.header.conditioning)},
                {"chunk", p.model.header.arch.chunk},
                {"bins", p.model.header.arch.bins},
                {"phase_ticks", p.phase_ticks},
                {"precision", weightPrecisionName(p.precision)},
                {"kernel", policyKernelName(activePolicyKernel())}};
  j["reference"] = p.reference.description;
  j["retarget"] = {{"priority", retargetPriorityName(p.retarget.priority)},
                   {"lambda_q", p.retarget.lambda_q},
                   {"posture_weights", std::vector<double>(p.retarget.posture_weights.data(),
                                                           p.retarget.posture_weights.data() + kNumJoints)}};
  j["movement"] = p.spec.movement;
  j["seed"] = o.seed;
  j["realtime"] = o.realtime;
  if (o.realtime) {
    j["realtime_scheduling"] = totals.realtime_scheduling;
    j["skipped_periods"] = totals.skipped_periods;
  }
  j["zero_timing"] = o.zero_timing;
  j["robot"] = totals.lola ? "lola" : "ode";
  if (totals.lola) {
    const LolaCounters& c = totals.lola_counters;
    std::vector<double> rtt_us;
    rtt_us.reserve(totals.lola_latency_ns.size());
    for (std::int64_t ns : totals.lola_latency_ns) rtt_us.push_back(static_cast<double>(ns) * 1e-3);
    j["lola"] = {{"socket", totals.lola_socket},
                 {"cycles", c.cycles},
                 {"late", c.late},
                 {"malformed", c.malformed},
                 {"gaps", c.gaps},
                 {"hot_cycles", c.hot_cycles},
                 {"tracking_cycles", c.tracking_cycles},
                 {"io_thread", o.lola.io_thread},
                 {"overrun_ticks", c.overrun_ticks},
                 {"warm", c.before_tick_calls > 0},
                 {"warm_skipped", c.before_tick_skipped},
                 {"warm_us_mean", c.before_tick_calls > 0 ? ordered_json(1e-3 * static_cast<double>(c.before_tick_ns) /
                                                                         static_cast<double>(c.before_tick_calls))
                                                          : ordered_json(nullptr)},
                 {"io_allocations", c.io_allocations >= 0 ? ordered_json(c.io_allocations) : ordered_json(nullptr)},
                 {"round_trip_us", statsJson(latencyStats(rtt_us))},
                 {"stop", totals.stop == RobotStop::kLinkLost ? "link_lost"
                          : totals.stop == RobotStop::kSignal ? "signal"
                                                              : "end_of_run"}};
  } else {
    j["lola"] = nullptr;
  }
  j["wall_s"] = totals.wall_s;
  j["attention"] = {{"file", logging ? ordered_json("attention.bin") : ordered_json(nullptr)},
                    {"shm", o.attention_shm.empty() ? ordered_json(nullptr) : ordered_json(o.attention_shm)},
                    {"records_written", attention.records_written},
                    {"first_record", attention.first_record},
                    {"record_count", attention.record_count}};
  report.summary_json = j.dump(2) + "\n";
  if (logging) writeText(dir / "summary.json", report.summary_json);

  // The human summary.
  std::ostringstream s;
  char buf[256];
  std::snprintf(buf, sizeof buf, "  ticks        %lld (%.1f s simulated, %.2f s wall, %s)\n",
                static_cast<long long>(report.ticks), static_cast<double>(report.ticks) * o.controller.period_s,
                totals.wall_s, o.realtime ? "real time" : "back to back");
  s << buf;
  std::string fault_text;
  for (int b = 0; b < kNumControllerFaults; ++b)
    if (report.faults[static_cast<std::size_t>(b)] > 0)
      fault_text += (fault_text.empty() ? "" : ", ") + std::string(kControllerFaultNames[static_cast<std::size_t>(b)]) +
                    " " + std::to_string(report.faults[static_cast<std::size_t>(b)]);
  s << "  faults       " << (fault_text.empty() ? "none" : fault_text) << "\n";
  if (n_ref > 0) {
    std::snprintf(buf, sizeof buf, "  ee RMSE      %.2f mm against the reference's feature-extracted trajectory (%lld ticks)\n",
                  report.ee_rmse_m * 1e3, static_cast<long long>(n_ref));
    s << buf;
  }
  if (p.spec.kind == ReferenceKind::kNone) {
    std::snprintf(buf, sizeof buf, "  ee DTW       %.2f mm mean hand-path distance to %zu validation demonstration(s)\n",
                  report.ee_dtw_m * 1e3, p.validation_demos.size());
    s << buf;
    if (report.ee_dtw_nearest_index >= 0) {
      std::snprintf(buf, sizeof buf, "  ee DTW near  %.2f mm to the nearest, %s\n", report.ee_dtw_nearest_m * 1e3,
                    p.validation.names[static_cast<std::size_t>(report.ee_dtw_nearest_index)].c_str());
      s << buf;
    }
  }
  s << "  tick         p50 " << millis(report.tick_us.p50) << ", p99 " << millis(report.tick_us.p99) << ", max "
    << millis(report.tick_us.max) << " (policy p99 " << millis(report.policy_us.p99) << ", overruns "
    << report.overruns << ")\n";
  s << "  allocations  "
    << (totals.allocations >= 0 ? std::to_string(totals.allocations) + " after activate" : std::string("not counted"))
    << "\n";
  if (logging)
    s << "  files        " << (dir / "ticks.csv").string() << ", " << (dir / "attention.bin").string() << " ("
      << attention.record_count << " records), " << (dir / "summary.json").string() << "\n";
  else
    s << "  files        none (--log DIR writes ticks.csv, attention.bin and summary.json)\n";
  out << s.str();
  out.flush();
}

}  // namespace nao::rt
