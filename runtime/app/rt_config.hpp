// What a nao_rt run is told and everything configured before its loop (docs/nao_rt.md):
// the options (rt_cli.hpp fills them), the model (compiled-in or --weights, checked; its weights
// bound), and the human reference the ticks see.
//
// References (--reference): where a run's human frames come from, one per tick.
//   file:PATH  a recorded 10 Hz skeleton CSV (nao_toolchain triangulate writes it), prepared at
//              configure time into fixed buffers (nao/reference_stream.hpp) with its evaluation
//              target, the demonstration's feature-extracted trajectory;
//   none       an autonomous-mode rollout from one of the model's starts (model.bin metadata
//              "starts", nao/model_file.hpp) or from --start-pose;
//   openpose:DIR0,DIR1[,...]  live cameras: OpenPose writing one folder per camera, read,
//              triangulated and filtered on a reader thread (rt_live.hpp, nao/live_camera.hpp);
//              the control thread takes the newest skeleton each tick.
// A kind is a ReferenceKind, parsed by parseReferenceSpec and turned into a HumanSource by
// prepareRun.
//
// Configure-time code: allocates, reads files, throws UsageError (exit 2) or another
// std::exception (exit 1) with a one-line message.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"
#include "nao/controller.hpp"
#include "nao/lola_backend.hpp"
#include "nao/model_file.hpp"
#include "nao/model_weights.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "nao/reference_stream.hpp"
#include "nao/sim_arm.hpp"

#include "allocation_probe.hpp"  // runtime/support

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

namespace nao::rt {

/// Counts the heap allocations of one helper thread of a run (the live camera's reader):
/// attach() runs first on that thread, count() reads the total from any thread (nao_rt backs it
/// with its counting allocator's ThreadAllocations).
struct ThreadAllocationCounter {
  virtual ~ThreadAllocationCounter() = default;
  virtual void attach() = 0;
  virtual std::int64_t count() const = 0;
};

/// Everything a run is told (the nao_rt command line, rt_cli.hpp).
struct RunOptions {
  std::string weights_path;                ///< model.bin; empty: the compiled-in model
  ModelImage compiled;                     ///< the compiled-in model (bytes nullptr if the build has none)
  /// fp32, fp32-packed or int8 (nao/quantize.hpp); empty: what the compiled-in model was
  /// generated with when no --weights is given, else fp32.
  std::string precision;
  /// The policy kernel (sse, avx2, avx512); empty: the best this CPU runs. Every kernel gives
  /// the same bits: the choice is speed only.
  std::string policy_kernel;
  std::string urdf_path = NAO_DEFAULT_URDF;
  std::string reference;       ///< file:PATH, none or openpose:DIR0,DIR1[,...]
  std::string movement;        ///< the movement, as named in model.bin (required)
  /// none only: the model's start of `movement` to roll out from (index into its "starts", 0-based);
  /// -1: not given (start 0 unless start_pose is).
  int start_index = -1;
  /// none only: 5 joint angles (rad) to start from instead of a model start; empty: none given.
  std::vector<double> start_pose;
  std::int64_t ticks = 0;      ///< > 0: run this many ticks
  double seconds = 0.0;        ///< > 0: run this long (rounded to whole ticks); else the default length
  bool realtime = false;       ///< absolute 10 Hz deadlines (clock_nanosleep), SCHED_FIFO + mlockall if permitted
  std::string log_dir;         ///< run directory; empty: no files
  std::string attention_shm;   ///< POSIX shared-memory name of the attention ring; empty: in process
  bool zero_timing = false;    ///< write the *_us columns of ticks.csv as 0 (byte-comparable files)
  ControllerParams controller; ///< fault timeouts, home pose, retargeting
  SimParams sim;               ///< the in-process ODE arm (--robot ode)
  /// The robot (makeRobotBackend, nao/robot_factory.hpp): ode (the in-process arm, default) or
  /// lola[:SOCKET] (LoLA, default socket /tmp/robocup).
  std::string robot = "ode";
  LolaParams lola;             ///< LoLA safety parameters (socket_path from `robot`)
  /// LoLA on one thread: load the policy's weights and workspace into the cache in the cycle
  /// before each tick's packet (warmPolicy; --lola-no-warm turns it off, docs/lola.md).
  bool lola_warm = true;
  ControllerClock* clock = nullptr;  ///< stage timings; nullptr: CLOCK_MONOTONIC (tests inject)
  // openpose: only (rt_live.hpp).
  std::string calibration_path;  ///< --calibration: the cameras, our JSON (nao/calibration_json.hpp)
  std::string pose_format;       ///< --format: body25 or body25b; empty: body25
  double fps = 0.0;              ///< --fps: capture rate, Hz; 0: 30
  double human_scale_m = 0.0;    ///< --human-scale: d_h, m; 0: the live source's estimate
  /// Counts the live camera reader thread's allocations (nao_rt: its counting allocator);
  /// nullptr: not counted (summary.json camera.reader_allocations null).
  ThreadAllocationCounter* reader_allocations = nullptr;
};


/// A command-line problem (unknown reference, missing --movement, ...): exit status 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Counts heap allocations on the calling thread between start and stop (nao_rt and the
/// *_alloc tests back it with CountAllocations; without one the summary says null): the control
/// thread's, summary.json allocations_after_activate. The LoLA backend's I/O thread
/// (--lola-io-thread) is counted apart by the probe's companion(), started and stopped on that
/// thread (summary.json lola.io_allocations).
using nao::AllocationProbe;

/// Longest run: one hour of ticks (NAO's battery lasts about that). The run buffers are sized
/// by it before the loop, so a larger count would only allocate until the machine gives up.
inline constexpr std::int64_t kMaxRunTicks = kMaxStartTicks;

/// Replaces line breaks so a message stays one line.
std::string oneLine(std::string s);

// ---------------------------------------------------------------------------------------------
// References.

enum class ReferenceKind {
  kFile,      ///< file:PATH, a recorded skeleton CSV
  kNone,      ///< none, an autonomous rollout from a start
  kOpenPose,  ///< openpose:DIR0,DIR1[,...], live cameras
};

struct ReferenceSpec {
  ReferenceKind kind = ReferenceKind::kFile;
  std::string movement;           ///< movement name as in model.bin
  std::string path;               ///< file: only
  std::vector<std::string> dirs;  ///< openpose: only, one folder per camera in calibration order
};

/// Parses --reference / --movement. Throws UsageError: no or an unknown reference, an empty
/// file: path, an openpose: list with fewer than 2 folders, an empty or repeated folder, no
/// --movement.
ReferenceSpec parseReferenceSpec(const std::string& reference, const std::string& movement);

/// The human scale a source measures live, to scale its last frame with.
struct LiveHumanScale {
  double scale_m = 0.0;  ///< d_h, m; 0: the run's configured scale
  double hand_m = 0.0;   ///< hand segment, m; 0: the per-frame rule (HumanKinematicsConfig)
};

/// The human frames a run's ticks see. Built at configure time; frameAt and scaleOfLastFrame
/// run on the control thread once per tick: real-time safe (no allocation, no lock, no I/O).
class HumanSource {
 public:
  virtual ~HumanSource() = default;
  /// The human of tick `tick` (world frame), or nullptr when nobody is seen in it.
  virtual const SkeletonFrame* frameAt(std::int64_t tick) = 0;
  /// The human scale to use with the frame frameAt last returned, for a source that estimates
  /// it live (rt_live.hpp); scale_m 0 (the default): the run's configured scale (a recorded
  /// reference's is calibrated at configure time from all its frames).
  virtual LiveHumanScale scaleOfLastFrame() const { return {}; }
};

class LiveSource;

// ---------------------------------------------------------------------------------------------
// The prepared run.

/// Everything configured before the policy is bound.
struct PreparedRun {
  ArmModel arm;
  ModelFile model;                     ///< validated, joints checked against `arm`
  std::string model_source;            ///< "compiled-in" or the --weights path
  const std::uint8_t* model_bytes = nullptr;  ///< compiled-in: the embedded bytes to bind to; else nullptr
  const std::uint64_t* model_offsets = nullptr;  ///< compiled-in: the generated tensor offsets
  const TensorExtent* model_extents = nullptr;   ///< compiled-in: the generated view extents
  WeightPrecision precision = WeightPrecision::kFp32;
  PolicyKernel kernel = bestPolicyKernel();  ///< what the weights are bound with (--policy-kernel)
  /// int8: the compiled-in blob (checked) to bind to; nullptr: quantise the model at start-up.
  const std::uint8_t* int8_bytes = nullptr;
  /// fp32-packed: the compiled-in packed blob (checked); nullptr: pack the model at start-up.
  const std::uint8_t* packed_bytes = nullptr;
  ReferenceSpec spec;
  int movement_index = 0;              ///< into model.header.movement_names
  std::vector<JointVector> centroids;  ///< the movement's key poses, rad
  /// The model's metadata (starts, workspace, run codes), its retargeting setting applied over
  /// options.controller.retarget.
  ModelSpec model_spec;
  std::unique_ptr<HumanSource> human;  ///< the frames the ticks see; nullptr: none (autonomous)
  /// file: the recorded reference (owned by `human`, so it stays put when the run is moved);
  /// nullptr for none.
  const ReferenceStream* reference = nullptr;
  /// openpose: the live source (owned by `human`; its camera's counters go to summary.json).
  const LiveSource* live = nullptr;
  std::string description;             ///< what the ticks see, e.g. "file:x.csv" or "none (start 2 ...)"
  /// none: the model start the run begins from (its name and index) or "" / -1 for --start-pose.
  std::string start_name;
  int start_index = -1;
  JointVector q_start = JointVector::Zero();  ///< activate pose (the arm starts there at rest, a(−1) = 0)
  std::int64_t ticks = 0;
  bool has_targets = false;            ///< the reference has a feature-extracted target per tick
};

/// Configure-time checks and preparation, in the order that fails fastest: options (openpose:
/// also its calibration), URDF, model (file checks, joints against the URDF, architecture against
/// `compiled_arch`), movement, conditioning, then the reference (the file, or the start), the
/// tick count and the run directory; last, openpose: starts the live source (its reader thread).
/// Throws UsageError or another std::exception with a one-line message.
PreparedRun prepareRun(const RunOptions& options, const PolicyArch& compiled_arch);

/// The kernel --policy-kernel names (empty: bestPolicyKernel()); throws on a name that is no
/// kernel or a kernel this CPU or build does not run.
PolicyKernel runPolicyKernel(const std::string& name);

// ---------------------------------------------------------------------------------------------
// Weights of a --weights file: copied at configure time into 64-byte aligned storage that the
// bound weights own (bindPolicyWeights, nao/model_weights.hpp). The compiled-in model is bound
// in place and costs nothing here. nao_bench reads its weights through copyWeightFile too, so
// it times what nao_rt reads.
using nao::copyWeightFile;
using nao::WeightStorage;

}  // namespace nao::rt
