// One nao_rt run (DESIGN §9, issue 5): configure everything (URDF, model, reference, controller,
// attention ring, run buffers), activate, run the 10 Hz loop, deactivate, then write the run
// directory (ticks.csv, attention.bin, summary.json; docs/nao_rt.md) and print a summary.
//
// A library (nao_rt_run) so that tests run it in process. runController is a template on the
// policy's compiled dimensions: nao_rt instantiates it with the compiled-in model's Dims
// (PaperPolicyDims when the build has no model), tests with SmallPolicyDims. Everything that
// does not depend on Dims lives in rt_run.cpp.
//
// Threads and time: configure and the file output run before and after the loop; between
// activate and deactivate the control thread only calls updateController, forward kinematics,
// and pushFromRT into preallocated memory — no allocation (counted through AllocationProbe),
// no file I/O, no lock. With --robot lola the robot backend's socket I/O is on this thread
// (the robot's packets are the clock), or with --lola-io-thread on the backend's own thread
// (lola_backend.hpp says why and when).
#pragma once

#include "nao/arm_model.hpp"
#include "nao/attention_ring.hpp"
#include "nao/controller.hpp"
#include "nao/kinematics.hpp"
#include "nao/lola_backend.hpp"
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "nao/tools/reference_source.hpp"
#include "rt_metrics.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <iosfwd>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

namespace nao::rt {

/// Everything a run is told (the nao_rt command line, rt_cli.hpp).
struct RunOptions {
  std::string weights_path;                ///< model.bin; empty: the compiled-in model
  ModelImage compiled;                     ///< the compiled-in model (bytes nullptr if the build has none)
  /// fp32 or int8 (nao/quantize.hpp); empty: int8 if the compiled-in model was generated so and
  /// no --weights is given, else fp32.
  std::string precision;
  std::string urdf_path = NAO_DEFAULT_URDF;
  /// synthetic:whole_arm|elbow|wrist, file:PATH or none.
  std::string reference = "synthetic:whole_arm";
  std::string movement;        ///< required for file: and none; implied by synthetic:
  std::uint64_t seed = 1;      ///< synthetic reference: run seed kReferenceSeedBase + seed
  /// none only: >= 0 starts the rollout at s_0 of this validation demonstration (index into
  /// the movement's held-out demonstrations, in split.val order) and runs its length; -1: the
  /// mean s_0 and mean length of all of them (--start-demo).
  int start_demo = -1;
  /// none only: >= 0 replaces the model's validation demonstrations by a test set, demonstrations
  /// 0 .. test_demos-1 of synthesiser run seed kReferenceSeedBase + test_seed (never a training or
  /// validation demonstration, and not selected on: the trainer never saw them), for --start-demo
  /// and the summary's nearest-demonstration DTW (--test-seed, --test-demos).
  std::int64_t test_seed = -1;
  int test_demos = 16;
  std::int64_t ticks = 0;      ///< > 0: run this many ticks
  double seconds = 0.0;        ///< > 0: run this long (rounded to whole ticks); else the default length
  bool realtime = false;       ///< absolute 10 Hz deadlines (clock_nanosleep), SCHED_FIFO + mlockall if permitted
  std::string log_dir;         ///< run directory; empty: no files
  std::string attention_shm;   ///< POSIX shared-memory name of the attention ring; empty: in process
  bool zero_timing = false;    ///< write the *_us columns of ticks.csv as 0 (byte-comparable files)
  ControllerParams controller; ///< fault timeouts, home pose, retargeting (defaults: DESIGN §9)
  SimParams sim;
  /// ode (the in-process arm, default) or lola[:SOCKET] (LoLA, default socket /tmp/robocup).
  std::string robot = "ode";
  LolaParams lola;             ///< LoLA safety parameters (socket_path from `robot`)
  /// LoLA on one thread: load the policy's weights and workspace into the cache in the cycle
  /// before each tick's packet (warmPolicy; --lola-no-warm turns it off, docs/lola.md).
  bool lola_warm = true;
  /// > 0: busy-wait this long before every tick's work, as a slower CPU would take (tests and
  /// benchmarks of the LoLA timing; not in tick_us).
  std::int64_t emulate_tick_ns = 0;
  ControllerClock* clock = nullptr;  ///< stage timings; nullptr: CLOCK_MONOTONIC (tests inject)
};

/// A command-line problem (unknown reference, missing --movement, ...): exit status 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Counts heap allocations on the calling thread between start and stop (nao_rt and the
/// *_alloc tests back it with CountAllocations; without one the summary says null). The LoLA
/// backend's I/O thread (--lola-io-thread) is counted by the probe's companion(), started and
/// stopped on that thread.
using nao::AllocationProbe;

/// What a run produced (also in summary.json).
/// Exit statuses of a run that the robot backend ended early (after its safe stop; the run
/// directory is still written).
inline constexpr int kExitRobotLinkLost = 3;  ///< LoLA socket closed or silent
inline constexpr int kExitStopSignal = 4;     ///< SIGINT/SIGTERM

struct RunReport {
  int status = 1;              ///< exit status: 0 done, 1 configure/load/output error, 2 usage error,
                               ///< kExitRobotLinkLost, kExitStopSignal
  std::string error;           ///< one line (without "nao_rt: ") when status != 0
  std::int64_t ticks = 0;
  std::int64_t overruns = 0;   ///< ticks that missed their deadline (--realtime only)
  std::array<std::int64_t, kNumControllerFaults> faults{};  ///< ticks with each fault bit
  std::int64_t allocations_after_activate = -1;            ///< -1: not counted
  double ee_rmse_m = std::numeric_limits<double>::quiet_NaN();
  double ee_dtw_m = std::numeric_limits<double>::quiet_NaN();
  /// none only: DTW to the nearest validation demonstration, and its index (-1: none).
  double ee_dtw_nearest_m = std::numeric_limits<double>::quiet_NaN();
  int ee_dtw_nearest_index = -1;
  LatencyStats tick_us, retarget_us, policy_us, sim_us;
  std::string summary_json;    ///< the text of summary.json (also without --log)
};

// ---------------------------------------------------------------------------------------------
// Configure-time pieces that do not depend on the compiled dimensions (rt_run.cpp).

enum class ReferenceKind { kSynthetic, kFile, kNone };

struct ReferenceSpec {
  ReferenceKind kind = ReferenceKind::kSynthetic;
  std::string movement;  ///< movement name as in model.bin
  std::string path;      ///< file: only
};

/// The robot backend a run drives (--robot).
struct RobotSpec {
  bool lola = false;
  std::string socket_path;  ///< lola only
};

/// Parses --robot: ode, lola, lola:PATH. Throws UsageError otherwise.
RobotSpec parseRobotSpec(const std::string& robot, const std::string& default_socket);

/// Parses --reference / --movement. Throws UsageError: unknown source, unknown movement,
/// --movement missing for file: and none, or contradicting synthetic:<movement>.
ReferenceSpec parseReferenceSpec(const std::string& reference, const std::string& movement);

/// The validation demonstrations of one movement named in a model's metadata (split.val,
/// written by nao_toolchain train), to be regenerated with the synthesiser.
struct ValidationSet {
  std::uint64_t seed = 1;      ///< synthesiser run seed of the data set
  bool seed_assumed = true;    ///< the metadata does not say it: the training set's seed 1 assumed
  std::vector<std::string> names;  ///< e.g. "elbow_003"
  std::vector<int> indices;        ///< demonstration index within the movement
};

/// Reads split.val (and data.synth_seed when present) from a model's metadata JSON and keeps the
/// demonstrations of `movement`. Throws std::runtime_error naming `origin` when there are none.
ValidationSet validationDemos(const std::string& metadata_json, const std::string& movement, const std::string& origin);

/// A test set of `movement`: demonstrations 0 .. count-1 of run seed kReferenceSeedBase +
/// test_seed (the seeds nao_rt's synthetic references come from, never a training seed), named
/// <movement>_test<seed>_<index>. Throws std::invalid_argument if count < 1.
ValidationSet testDemos(const std::string& movement, std::uint64_t test_seed, int count);

/// Everything configured before the policy is bound.
struct PreparedRun {
  ArmModel arm;
  ModelFile model;                     ///< validated, joints checked against `arm`
  std::string model_source;            ///< "compiled-in" or the --weights path
  const std::uint8_t* model_bytes = nullptr;  ///< compiled-in: the embedded bytes to bind to; else nullptr
  const std::uint64_t* model_offsets = nullptr;  ///< compiled-in: the generated tensor offsets
  WeightPrecision precision = WeightPrecision::kFp32;
  /// int8: the compiled-in blob (checked) to bind to; nullptr: quantise the model at start-up.
  const std::uint8_t* int8_bytes = nullptr;
  /// fp32-packed: the compiled-in packed blob (checked); nullptr: pack the model at start-up.
  const std::uint8_t* packed_bytes = nullptr;
  ReferenceSpec spec;
  int movement_index = 0;              ///< into model.header.movement_names
  std::vector<JointVector> centroids;  ///< the movement's key poses, rad
  RetargetParams retarget;             ///< options.controller.retarget with the model's setting applied
  std::int64_t phase_ticks = 0;        ///< the model's training.phase_ticks (ControllerParams)
  tools::ReferenceStream reference;    ///< synthetic/file (empty for none)
  ValidationSet validation;            ///< none only
  std::vector<tools::ReferenceStream> validation_demos;  ///< none only
  JointVector q_start = JointVector::Zero();  ///< activate pose
  std::int64_t ticks = 0;
  bool has_targets = false;            ///< the reference has a feature-extracted target per tick
};

/// `defaults` with the retargeting setting a model's metadata records (data.retarget: priority,
/// lambda_q, posture_weights) applied; unchanged when the metadata has none. Throws
/// std::runtime_error naming `origin` for a setting that is present but unusable.
RetargetParams modelRetargetSetting(const std::string& metadata_json, const RetargetParams& defaults,
                                    const std::string& origin);

/// The phase grid an autonomous model's step embedding was trained on (metadata
/// training.phase_ticks, ControllerParams::phase_ticks); 0 when the metadata has none. Throws
/// std::runtime_error naming `origin` for a value that is present but not an integer in [1, 1e5].
std::int64_t modelPhaseTicks(const std::string& metadata_json, const std::string& origin);

/// Configure-time checks and preparation, in the order that fails fastest: reference syntax,
/// URDF, model (file checks, joints against the URDF, architecture against `compiled_arch`),
/// movement, conditioning, then the reference stream or the validation demonstrations, the
/// tick count and the run directory. Throws UsageError or another std::exception with a
/// one-line message.
PreparedRun prepareRun(const RunOptions& options, const PolicyArch& compiled_arch);

/// ticks.csv's header line (no newline): the columns in order.
std::string ticksCsvHeader();

/// One ticks.csv row (no newline): doubles in shortest round-trip form, `_us` columns 0 when
/// zero_timing.
std::string ticksCsvRow(const TickRecord& r, bool zero_timing);

/// Result of trying real-time scheduling (SCHED_FIFO + mlockall).
struct RealtimeScheduling {
  bool fifo = false;
  bool locked = false;
  int old_policy = 0;
  int old_priority = 0;
  std::string warning;  ///< one line when something was not permitted
};
RealtimeScheduling enterRealtime();
void leaveRealtime(const RealtimeScheduling& s);
/// Sleeps until the absolute CLOCK_MONOTONIC time t_ns (clock_nanosleep TIMER_ABSTIME; resumes
/// after signals). Real-time safe.
void sleepUntilNs(std::int64_t t_ns);
/// Busy-waits ns nanoseconds (RunOptions::emulate_tick_ns): no syscall but the clock read.
void spinForNs(std::int64_t ns);

/// What the loop measured beyond the records.
struct LoopTotals {
  std::int64_t allocations = -1;
  std::int64_t skipped_periods = 0;  ///< --realtime: whole periods skipped after overruns
  double wall_s = 0.0;
  std::string realtime_scheduling;   ///< "SCHED_FIFO + mlockall", or what was not permitted
  bool lola = false;                 ///< the robot was LoLA (summary.json "robot", "lola")
  std::string lola_socket;
  LolaCounters lola_counters;
  std::vector<std::int64_t> lola_latency_ns;  ///< per answered cycle
  RobotStop stop = RobotStop::kNone;          ///< the backend ended the run early
};

/// After the loop: metrics, summary.json, ticks.csv, attention.bin (from `ring`), the printed
/// summary on `out`. Throws std::runtime_error on output errors.
void finishRun(const RunOptions& options, const PreparedRun& prepared, const std::vector<TickRecord>& records,
               const AttentionRingView& ring, const LoopTotals& totals, std::ostream& out, RunReport& report);

/// Replaces line breaks so a message stays one line.
std::string oneLine(std::string s);

// ---------------------------------------------------------------------------------------------
// Weights of a --weights file (DESIGN §8): copied at configure time into 64-byte aligned storage
// that exists only when a file is loaded. The compiled-in model is bound in place and costs
// nothing here (this replaced a 24 MB static array in .bss; issue 14).

/// The aligned floats a --weights model's tensors are copied into; empty (no memory) for the
/// compiled-in model. Owned by the run, alive until the loop has ended.
struct WeightStorage {
  struct Free {
    void operator()(float* f) const noexcept { ::operator delete[](f, std::align_val_t{kModelAlignment}); }
  };
  std::unique_ptr<float[], Free> floats;
  std::size_t n_floats = 0;
};

/// Copies the tensors of `model` into `storage` (allocated here: every tensor of its table, each
/// padded to 64 bytes, 64-byte aligned, zero-filled, so the padding between tensors reads as
/// zeros) and returns where each one starts, in manifest order. Configure time: allocates;
/// throws std::bad_alloc. nao_bench reads its weights from here too, so it times what nao_rt reads.
inline std::vector<const float*> copyWeightFile(const ModelFile& model, WeightStorage& storage) {
  std::vector<const float*> pointers;
  pointers.reserve(model.tensors.size());
  storage.n_floats = 0;
  for (const TensorEntry& t : model.tensors) storage.n_floats += (t.spec.count() + 15) / 16 * 16;
  storage.floats.reset(static_cast<float*>(
      ::operator new[](storage.n_floats * sizeof(float), std::align_val_t{kModelAlignment})));
  float* floats = storage.floats.get();
  std::fill(floats, floats + storage.n_floats, 0.0f);
  std::size_t used = 0;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) {
    const std::size_t n = model.tensors[i].spec.count();
    if (used + n > storage.n_floats)
      throw std::logic_error("nao_rt: the weight storage is smaller than the model's manifest");
    std::memcpy(floats + used, model.data(i), n * sizeof(float));
    pointers.push_back(floats + used);
    used += (n + 15) / 16 * 16;
  }
  return pointers;
}

/// The weights of a --weights model: copyWeightFile, the views bound by name.
template <class Dims>
PolicyWeights<Dims> bindWeightFile(const PreparedRun& p, WeightStorage& storage) {
  const std::vector<const float*> pointers = copyWeightFile(p.model, storage);
  return bindPolicyWeights<Dims>(pointers.data(), pointers.size(), p.model.header.arch, p.model.header.conditioning);
}

// ---------------------------------------------------------------------------------------------
// The run.

template <class Dims>
using RunPayload = AttentionPayload<Dims::kDecoderLayers, Dims::kHeads, Dims::kDModel, Dims::kWindow>;
template <class Dims>
using RunRing = AttentionRing<RunPayload<Dims>, kDefaultAttentionCapacity>;

namespace detail {

/// The attention ring, in process or in shared memory (--attention-shm).
template <class Ring>
struct RingHolder {
  std::unique_ptr<Ring> local;
  std::unique_ptr<SharedAttentionRing<Ring>> shared;
  Ring& ring() { return shared ? shared->ring() : *local; }
};

/// Fills and seals the tick's attention record from the record and the policy workspace.
/// Real-time safe.
template <class Dims>
void fillPayload(const TickRecord& rec, const PolicyWorkspace<Dims>& ws, RunPayload<Dims>& payload) {
  using P = RunPayload<Dims>;
  static_assert(sizeof(P::cross) == sizeof(ws.cross), "payload and workspace cross-attention differ in shape");
  static_assert(sizeof(P::cross_out) == sizeof(float) * Dims::kDModel * Dims::kTokens,
                "payload and workspace cross-attention output differ in shape");
  payload.tick = static_cast<std::uint64_t>(rec.tick);
  payload.fault = rec.fault;
  payload.reserved = 0;
  for (int j = 0; j < Dims::kTokens; ++j) {
    payload.score[j] = rec.att[static_cast<std::size_t>(j)];
    payload.mass[j] = rec.attm[static_cast<std::size_t>(j)];
  }
  // Like cross: the workspace's last policy step (a bypassed tick shows in the fault bits).
  for (int a = 0; a < Dims::kWindow; ++a) payload.age_profile[a] = ws.age_profile[a];
  std::memcpy(payload.cross, ws.cross, sizeof(payload.cross));
  // Column i of the workspace's [D, J] column-major matrix is action token i: row i of cross_out.
  std::memcpy(payload.cross_out, ws.cross_out.data(), sizeof(payload.cross_out));
  sealPayload(payload);
}

}  // namespace detail

/// Runs nao_rt once with the policy compiled as Dims (see the top of this file). Never throws:
/// a problem ends the run with report.status != 0 and report.error set (one line).
/// @param out   the human summary (and the configuration line)
/// @param err   warnings (--realtime not permitted)
/// @param probe allocation counter around activate ... deactivate; nullptr: not counted
template <class Dims>
RunReport runController(const RunOptions& options, std::ostream& out, std::ostream& err,
                        AllocationProbe* probe = nullptr) {
  RunReport report;
  try {
    // Configure: everything that can fail or allocate.
    const RobotSpec robot = parseRobotSpec(options.robot, options.lola.socket_path);
    if (robot.lola && options.realtime)
      throw UsageError("--realtime paces the in-process arm; with --robot lola the robot's packets are the clock");
    PreparedRun p = prepareRun(options, Dims::arch());
    WeightStorage weight_storage;
    // The compiled-in model: views at the generated offsets into .rodata (no lookup, no copy);
    // a --weights file: its tensors copied into aligned storage, bound by name.
    PolicyWeights<Dims> weights =
        p.model_bytes != nullptr
            ? bindPolicyWeightsAt<Dims>(p.model_bytes, p.model_offsets, p.model.header.arch,
                                        p.model.header.conditioning)
            : bindWeightFile<Dims>(p, weight_storage);
    // The views point into the compiled-in bytes or weight_storage: the decoded file copy is no
    // longer read, so its memory goes back now, before an int8 or packed copy is made from the
    // views (one fp32 copy resident at a time: docs/embedded.md, RSS).
    std::vector<std::uint8_t>().swap(p.model.bytes);
    // int8: the compiled-in blob where it lies, or the same bytes made from the fp32 views.
    // copy_storage: the int8 or packed copy made at start-up (none for a compiled-in one).
    AlignedBytes copy_storage;
    if (p.precision == WeightPrecision::kInt8) {
      if constexpr (int8Supported<Dims>()) {
        const std::uint8_t* blob = p.int8_bytes;
        if (blob == nullptr) {
          copy_storage = quantizePolicyInt8<Dims>(weights);
          blob = copy_storage.data.get();
        }
        if (quantizedModelBytes(p.model.header.arch) != quantizedPolicyBytes<Dims>())
          throw std::logic_error("nao_rt: the int8 blob of the model is not the compiled layout's size");
        bindQuantizedWeights<Dims>(weights, blob);
      } else {
        throw std::runtime_error("--precision int8: this architecture has an odd or over-512 input size; int8 "
                                 "needs even input sizes up to 512");
      }
    }
    // fp32-packed: the same floats in the kernels' block order, compiled in (nao_codegen
    // --precision fp32-packed) or made at start-up.
    if (p.precision == WeightPrecision::kFp32Packed) {
      if constexpr (packedSupported<Dims>()) {
        const std::uint8_t* blob = p.packed_bytes;
        if (blob == nullptr) {
          copy_storage = packPolicyFp32<Dims>(weights);
          blob = copy_storage.data.get();
        }
        if (packedModelBytes(p.model.header.arch) != packedPolicyBytes<Dims>())
          throw std::logic_error("nao_rt: the packed blob of the model is not the compiled layout's size");
        bindPackedWeights<Dims>(weights, blob);
      } else {
        throw std::runtime_error("--precision fp32-packed: this architecture has a matrix the packed layout does "
                                 "not take (outputs in multiples of 32, inputs of 16)");
      }
    }
    ControllerParams controller_params = options.controller;
    controller_params.phase_ticks = p.phase_ticks;  // the run's length sets the pace of a phase model
    controller_params.run_ticks = p.ticks;
    controller_params.retarget = p.retarget;
    // The human's scale d_h is calibrated once per reference, as the training data and the
    // evaluation target were retargeted (one scale per demonstration from all its frames:
    // toolchain retargetTargets), not re-estimated per frame: per-frame link lengths jitter with
    // the keypoint noise, which moved the hand target, flipped key-pose snaps and left the
    // controller tracking another trajectory than the one it is scored against.
    if (controller_params.human.scale_m <= 0.0 && p.reference.human.scale_m > 0.0)
      controller_params.human = p.reference.human;
    const ControllerModel<Dims> model = configureController(p.arm, weights, controller_params, options.sim);
    auto data = std::make_unique<ControllerData<Dims>>(model.sim, p.q_start);
    std::unique_ptr<LolaBackend> lola;
    // What the cycle before a tick's packet warms (LolaParams::before_tick).
    struct WarmContext {
      const PolicyWeights<Dims>* weights;
      const PolicyWorkspace<Dims>* workspace;
      std::uint64_t sink;
    } warm{&model.policy, data->policy.get(), 0};
    if (robot.lola) {
      // The socket is opened here, before activate.
      LolaParams lola_params = options.lola;
      lola_params.socket_path = robot.socket_path;
      lola_params.io_probe = probe != nullptr ? probe->companion() : nullptr;
      if (options.lola_warm && !lola_params.io_thread) {
        lola_params.before_tick = [](void* c) {
          auto* w = static_cast<WarmContext*>(c);
          warmPolicy(*w->weights, *w->workspace, w->sink);
        };
        lola_params.before_tick_context = &warm;
      }
      installLolaStopSignals();
      lola = std::make_unique<LolaBackend>(p.arm, lola_params);
      data->robot = lola.get();
    }
    detail::RingHolder<RunRing<Dims>> rings;
    const AttentionDescriptor descriptor = attentionPayloadDescriptor<RunPayload<Dims>>();
    if (options.attention_shm.empty())
      rings.local = std::make_unique<RunRing<Dims>>(descriptor);
    else
      rings.shared = std::make_unique<SharedAttentionRing<RunRing<Dims>>>(options.attention_shm, descriptor);
    RunRing<Dims>& ring = rings.ring();
    auto payload = std::make_unique<RunPayload<Dims>>();
    std::vector<TickRecord> records(static_cast<std::size_t>(p.ticks));
    ArmData kin_ref;
    SteadyClock steady;
    ControllerClock& clock = options.clock != nullptr ? *options.clock : steady;
    const std::size_t n_frames = p.reference.frames.size();
    const std::int64_t period_ns = static_cast<std::int64_t>(options.controller.period_s * 1e9 + 0.5);

    LoopTotals totals;
    RealtimeScheduling rt;
    if (options.realtime) {
      rt = enterRealtime();
      if (!rt.warning.empty()) err << "nao_rt: warning: " << rt.warning << "\n";
      totals.realtime_scheduling = rt.warning.empty() ? "SCHED_FIFO + mlockall" : rt.warning;
    }
    out << "nao_rt: " << p.reference.description << " -> movement " << p.spec.movement << ", model " << p.model_source << ", " << p.ticks << " ticks ("
        << static_cast<double>(p.ticks) * options.controller.period_s << " s), "
        << (robot.lola ? "on LoLA " + robot.socket_path : options.realtime ? "real time" : "back to back") << "\n";
    out.flush();

    // Every page the step reads resident before the loop (a released image's, a --weights
    // copy's): one pass over them, no page fault on the first tick.
    {
      std::uint64_t sink = 0;
      warmPolicy(model.policy, *data->policy, sink);
      warm.sink += sink;
    }
    // The loop: no allocation, no I/O, no exception from here to deactivate.
    if (probe != nullptr) probe->start();
    const std::int64_t wall0 = monotonicNs();
    activateController(model, *data, p.q_start, p.movement_index, clock);
    std::int64_t next_ns = monotonicNs();
    std::int64_t ticks_done = 0;
    for (std::int64_t t = 0; t < p.ticks && data->robot->stopReason() == RobotStop::kNone; ++t) {
      if (options.realtime) sleepUntilNs(next_ns);
      if (options.emulate_tick_ns > 0) spinForNs(options.emulate_tick_ns);
      const std::size_t i = static_cast<std::size_t>(t);
      const SkeletonFrame* frame = i < n_frames && p.reference.present[i] ? &p.reference.frames[i] : nullptr;
      TickRecord& rec = records[i];
      rec = updateController(model, *data, frame);
      // Where the arm should be at the end of the tick: the reference's feature-extracted pose
      // of the next sample (the last one held at the end).
      if (p.has_targets && i < n_frames)
        rec.ee_ref = forwardKinematics(p.arm, kin_ref, p.reference.target[std::min(i + 1, n_frames - 1)]);
      else
        rec.ee_ref.setConstant(std::numeric_limits<double>::quiet_NaN());
      if (options.realtime) {
        // Overrun: the tick ended after the next grid point. Stay on the grid: the next tick
        // starts at the first grid point still ahead.
        const std::int64_t deadline = next_ns + period_ns;
        const std::int64_t now = monotonicNs();
        if (now > deadline) {
          rec.fault |= kFaultOverrun;
          const std::int64_t missed = (now - deadline) / period_ns + 1;
          totals.skipped_periods += missed;
          next_ns = deadline + missed * period_ns;
        } else {
          next_ns = deadline;
        }
      } else {
        // Back to back there is no deadline to miss: the fault column stays free of timing.
        rec.fault &= ~static_cast<std::uint32_t>(kFaultOverrun);
      }
      detail::fillPayload<Dims>(rec, *data->policy, *payload);
      pushFromRT(ring, *payload);
      ticks_done = t + 1;
    }
    const RobotStop stop = data->robot->stopReason();
    deactivateController(model, *data);
    closeFromRT(ring);
    totals.wall_s = static_cast<double>(monotonicNs() - wall0) * 1e-9;
    if (probe != nullptr) totals.allocations = probe->stop();
    // The LoLA I/O thread's own count (it stopped its probe before deactivate joined it).
    if (lola && lola->counters().io_allocations > 0 && totals.allocations >= 0)
      totals.allocations += lola->counters().io_allocations;
    if (options.realtime) leaveRealtime(rt);
    records.resize(static_cast<std::size_t>(ticks_done));
    totals.stop = stop;
    if (lola) {
      totals.lola = true;
      totals.lola_socket = robot.socket_path;
      totals.lola_counters = lola->counters();
      totals.lola_latency_ns = lola->latenciesNs();
    }

    finishRun(options, p, records, attentionRingView(ring), totals, out, report);
    report.status = 0;
    if (stop == RobotStop::kLinkLost) {
      report.status = kExitRobotLinkLost;
      report.error = "the robot's LoLA link was lost after " + std::to_string(ticks_done) + " of " +
                     std::to_string(p.ticks) + " ticks (run directory written)";
    } else if (stop == RobotStop::kSignal) {
      report.status = kExitStopSignal;
      report.error = "stopped by a signal after " + std::to_string(ticks_done) + " of " + std::to_string(p.ticks) +
                     " ticks: held, stiffness ramped to 0 (run directory written)";
    }
  } catch (const UsageError& e) {
    report.status = 2;
    report.error = oneLine(e.what());
  } catch (const std::exception& e) {
    report.status = 1;
    report.error = oneLine(e.what());
  } catch (...) {
    report.status = 1;
    report.error = "unexpected error";
  }
  return report;
}

/// runController, then the error (if any) as one line "nao_rt: <message>" on `err`. Returns
/// the exit status.
template <class Dims>
int runMain(const RunOptions& options, std::ostream& out, std::ostream& err, AllocationProbe* probe = nullptr) {
  const RunReport r = runController<Dims>(options, out, err, probe);
  if (r.status != 0) err << "nao_rt: " << r.error << "\n";
  return r.status;
}

}  // namespace nao::rt
