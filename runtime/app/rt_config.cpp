// Configure-time preparation of a nao_rt run (rt_config.hpp).
#include "nao/arm_model_io.hpp"
#include "rt_config.hpp"

#include "rt_live.hpp"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <utility>

namespace nao::rt {
namespace {

namespace fs = std::filesystem;

constexpr const char* kReferenceHelp =
    "file:PATH (a 10 Hz skeleton CSV), none (an autonomous rollout) or openpose:DIR0,DIR1[,...] (live cameras)";
constexpr const char* kMaxRunText = "36000 ticks (1 h at 10 Hz)";

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// A recorded reference: the prepared frames, tick by tick; nobody past its end.
class RecordedSource final : public HumanSource {
 public:
  explicit RecordedSource(ReferenceStream stream) : stream_(std::move(stream)) {}
  const SkeletonFrame* frameAt(std::int64_t tick) override {
    const std::size_t i = static_cast<std::size_t>(tick);
    return tick >= 0 && i < stream_.frames.size() && stream_.present[i] ? &stream_.frames[i] : nullptr;
  }
  const ReferenceStream& stream() const { return stream_; }

 private:
  ReferenceStream stream_;
};

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
    p.model_extents = o.compiled.extents;
  } else {
    throw std::runtime_error(
        "no model is compiled into this build (models/default.bin did not exist when it was built); pass "
        "--weights FILE, or build one with the model compiled in: toolchain/nao build --model FILE");
  }
  // Precision: asked for, or what the compiled-in model was generated with (fp32 for --weights).
  p.precision = runPrecision(o.precision, p.model_bytes != nullptr, o.compiled);
  p.kernel = runPolicyKernel(o.policy_kernel);
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
    // The compiled architecture is a build choice: say which build runs this model.
    throw std::runtime_error(origin + ": " + e.what() + "; build a nao_rt for it: toolchain/nao build --model " +
                             origin);
  }
}

// The start pose of --start-pose: 5 finite angles, rad.
JointVector startPose(const std::vector<double>& v) {
  if (v.size() != static_cast<std::size_t>(kNumJoints))
    throw UsageError("--start-pose needs " + std::to_string(kNumJoints) + " joint angles q0,q1,q2,q3,q4 (rad), got " +
                     std::to_string(v.size()));
  JointVector q;
  for (int j = 0; j < kNumJoints; ++j) {
    if (!std::isfinite(v[static_cast<std::size_t>(j)])) throw UsageError("--start-pose: joint angles must be finite");
    q[j] = v[static_cast<std::size_t>(j)];
  }
  return q;
}

// --reference none: the start (a model start or --start-pose), the default length, the description.
void prepareAutonomousStart(const RunOptions& o, PreparedRun& p, std::int64_t& default_ticks) {
  const std::vector<ModelStart>& starts = p.model_spec.starts[static_cast<std::size_t>(p.movement_index)];
  const std::string& m = p.spec.movement;
  if (!o.start_pose.empty()) {
    p.q_start = startPose(o.start_pose);
    p.description = "none (rollout of " + m + " from --start-pose)";
    if (!starts.empty()) {
      // The mean length of the movement's starts: how long its demonstrations were.
      double sum = 0.0;
      for (const ModelStart& s : starts) sum += static_cast<double>(s.ticks);
      default_ticks = std::llround(sum / static_cast<double>(starts.size()));
    } else if (o.ticks <= 0 && o.seconds <= 0.0) {
      throw UsageError("--start-pose: " + p.model_source + " carries no starts of " + m +
                       " to take a run length from: give --ticks N or --seconds S");
    }
    return;
  }
  if (starts.empty())
    throw UsageError("--reference none: " + p.model_source + " carries no autonomous starts of " + m +
                     " (model.bin metadata \"starts\"; nao_toolchain model-starts adds them): give --start-pose "
                     "q0,q1,q2,q3,q4");
  const int index = o.start_index >= 0 ? o.start_index : 0;
  if (index >= static_cast<int>(starts.size()))
    throw UsageError("--start " + std::to_string(index) + ": " + p.model_source + " has " +
                     std::to_string(starts.size()) + " start(s) of " + m + " (0.." +
                     std::to_string(starts.size() - 1) + ")");
  const ModelStart& s = starts[static_cast<std::size_t>(index)];
  p.q_start = s.q;
  p.start_name = s.name;
  p.start_index = index;
  default_ticks = s.ticks;
  p.description = "none (rollout of " + m + " from start " + std::to_string(index) + " of " +
                  std::to_string(starts.size()) + ", " + s.name + ")";
}

}  // namespace

std::string oneLine(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  return s;
}

ReferenceSpec parseReferenceSpec(const std::string& reference, const std::string& movement) {
  ReferenceSpec s;
  if (reference.empty()) throw UsageError(std::string("--reference is required: ") + kReferenceHelp);
  if (reference == "none") {
    s.kind = ReferenceKind::kNone;
  } else if (startsWith(reference, "file:")) {
    s.kind = ReferenceKind::kFile;
    s.path = reference.substr(5);
    if (s.path.empty()) throw UsageError("--reference file: needs a path (file:PATH)");
  } else if (startsWith(reference, "openpose:")) {
    s.kind = ReferenceKind::kOpenPose;
    const std::string list = reference.substr(9);
    for (std::size_t begin = 0;;) {
      const std::size_t comma = list.find(',', begin);
      s.dirs.push_back(list.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin));
      if (comma == std::string::npos) break;
      begin = comma + 1;
    }
    for (std::size_t a = 0; a < s.dirs.size(); ++a) {
      if (s.dirs[a].empty())
        throw UsageError("--reference openpose: folder " + std::to_string(a) +
                         " is empty (openpose:DIR0,DIR1[,...], one folder per camera)");
      for (std::size_t b = 0; b < a; ++b)
        if (fs::path(s.dirs[a]).lexically_normal() == fs::path(s.dirs[b]).lexically_normal())
          throw UsageError("--reference openpose: folder " + s.dirs[a] + " is given for two cameras");
    }
    if (s.dirs.size() < 2)
      throw UsageError("--reference openpose: needs a folder per camera and at least 2 cameras "
                       "(openpose:DIR0,DIR1[,...])");
  } else {
    throw UsageError("unknown reference '" + reference + "' (" + kReferenceHelp + ")");
  }
  if (movement.empty())
    throw UsageError("--reference " + reference + " needs --movement M (the movement as named in model.bin)");
  s.movement = movement;
  return s;
}

PolicyKernel runPolicyKernel(const std::string& name) {
  if (name.empty()) return bestPolicyKernel();
  PolicyKernel k{};
  if (!parsePolicyKernel(name, k)) throw std::invalid_argument("--policy-kernel " + name + ": not sse, avx2 or avx512");
  requirePolicyKernel(k);
  return k;
}

PreparedRun prepareRun(const RunOptions& o, const PolicyArch& compiled_arch) {
  PreparedRun p;
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
  p.spec = parseReferenceSpec(o.reference, o.movement);
  const bool autonomous_run = p.spec.kind == ReferenceKind::kNone;
  if (o.start_index >= 0 && !autonomous_run)
    throw UsageError("--start needs --reference none (it picks the model's start to roll out from)");
  if (!o.start_pose.empty() && !autonomous_run)
    throw UsageError("--start-pose needs --reference none (a recorded reference starts where it starts)");
  if (o.start_index >= 0 && !o.start_pose.empty())
    throw UsageError("--start and --start-pose exclude each other");
  if (!o.start_pose.empty()) startPose(o.start_pose);  // a bad pose is a usage error before any file is read
  const bool live_run = p.spec.kind == ReferenceKind::kOpenPose;
  if (!live_run) {
    for (const auto& [given, flag] : {std::pair{!o.calibration_path.empty(), "--calibration"},
                                      std::pair{!o.pose_format.empty(), "--format"}, std::pair{o.fps != 0.0, "--fps"},
                                      std::pair{o.human_scale_m != 0.0, "--human-scale"}})
      if (given) throw UsageError(std::string(flag) + " needs --reference openpose:DIR0,DIR1[,...] (live cameras)");
  } else if (o.ticks <= 0 && o.seconds <= 0.0) {
    throw UsageError("--reference openpose: a live run has no length of its own: give --seconds S or --ticks N");
  }
  // The live source's configuration (a bad flag value is a usage error before any file is read
  // but the calibration).
  std::optional<LiveCameraConfig> live_config;
  if (live_run) live_config = liveCameraConfig(o, p.spec);
  checkSimPeriod(o.sim, o.controller.period_s);

  p.arm = loadArmModel(o.urdf_path);
  loadModel(o, compiled_arch, p);
  const ModelHeader& h = p.model.header;
  const auto it = std::find(h.movement_names.begin(), h.movement_names.end(), p.spec.movement);
  if (it == h.movement_names.end())
    throw std::runtime_error("the model (" + p.model_source + ") has no movement '" + p.spec.movement +
                             "' (it has: " + joined(h.movement_names) + ")");
  p.movement_index = static_cast<int>(it - h.movement_names.begin());
  if (live_run && h.conditioning == Conditioning::kAutonomous)
    throw std::runtime_error("--reference openpose: needs a reference-conditioned model; " + p.model_source +
                             " is an autonomous-mode model (it ignores the human: use --reference none)");
  if (autonomous_run && h.conditioning != Conditioning::kAutonomous)
    throw std::runtime_error("--reference none needs an autonomous-mode model; " + p.model_source +
                             " is reference-conditioned (it imitates a reference: use file:PATH)");
  p.centroids = modelKeyPoses(p.model, p.movement_index);
  // The starts, workspace, run codes and (next) the retargeting setting, decoded once.
  p.model_spec = readModelSpec(h, o.controller.retarget, p.model_source);
  // The reference is retargeted the way the model's training data was.

  std::int64_t default_ticks = 0;
  switch (p.spec.kind) {
    case ReferenceKind::kFile: {
      auto recorded = std::make_unique<RecordedSource>(
          makeFileReference(p.arm, p.spec.path, p.spec.movement, p.centroids, p.model_spec.retarget));
      const ReferenceStream& ref = recorded->stream();
      p.reference = &ref;
      p.human = std::move(recorded);
      p.description = ref.description;
      default_ticks = static_cast<std::int64_t>(ref.frames.size());
      p.has_targets = !ref.target.empty();
      // An autonomous model ignores the human: the reference is then only its evaluation target,
      // and its first target pose the start pose.
      p.q_start = p.has_targets ? ref.target.front() : o.controller.home;
      break;
    }
    case ReferenceKind::kNone:
      prepareAutonomousStart(o, p, default_ticks);
      break;
    case ReferenceKind::kOpenPose:
      // No recorded start: the arm starts at rest at home and is moved by the human it sees.
      p.description = liveDescription(o, p.spec);
      p.q_start = o.controller.home;
      break;
  }
  if (o.ticks > 0)
    p.ticks = o.ticks;
  else if (o.seconds > 0.0)
    p.ticks = std::max<std::int64_t>(1, std::llround(o.seconds / o.controller.period_s));
  else
    p.ticks = default_ticks;
  if (p.ticks <= 0) throw std::runtime_error("nothing to run: the reference has no ticks");
  if (p.ticks > kMaxRunTicks)
    throw std::runtime_error("the reference (" + p.description + ") has " + std::to_string(p.ticks) +
                             " ticks, more than the longest run, " + kMaxRunText + ": give --ticks or --seconds");

  if (!o.log_dir.empty()) {
    std::error_code ec;
    fs::create_directories(o.log_dir, ec);
    if (ec || !fs::is_directory(o.log_dir))
      throw std::runtime_error("cannot create the run directory " + o.log_dir + (ec ? ": " + ec.message() : ""));
    if (access(o.log_dir.c_str(), W_OK) != 0)
      throw std::runtime_error("cannot write into the run directory " + o.log_dir + ": " + std::strerror(errno));
  }
  if (live_config) {
    // Started last, once everything else has been checked: its reader thread watches the
    // folders from here on (files already in them are an earlier session's).
    auto live = std::make_unique<LiveSource>(std::move(*live_config));
    p.live = live.get();
    p.human = std::move(live);
  }
  return p;
}

}  // namespace nao::rt
