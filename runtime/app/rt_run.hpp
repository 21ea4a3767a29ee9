// One nao_rt run: configure (rt_config.hpp: URDF, model, reference, robot), activate,
// the 10 Hz loop, deactivate, then the run directory and the printed summary (rt_rundir.hpp).
//
// A library (nao_rt_run) so that tests run it in process. runController is a template on the
// policy's compiled dimensions: nao_rt instantiates it with the compiled-in model's Dims
// (PaperPolicyDims when the build has no model), tests with SmallPolicyDims.
//
// Threads and time: configure and the file output run before and after the loop; between
// activate and deactivate the control thread only calls the human source, the read -> update
// -> write cycle on the robot (runControllerTick), and pushFromRT into preallocated memory — no
// allocation (counted through AllocationProbe), no file I/O, no lock. With --robot lola the robot backend's socket I/O is on
// this thread (the robot's packets are the clock), or with --lola-io-thread on the backend's own
// thread (lola_backend.hpp says why and when). With --reference openpose the live camera's reader
// thread parses and triangulates beside the loop (rt_live.hpp). Each helper thread's allocations
// are counted apart from the control thread's (summary.json lola.io_allocations,
// camera.reader_allocations).
#pragma once

#include "rt_config.hpp"
#include "rt_rundir.hpp"

#include "nao/arm_model.hpp"
#include "nao/attention_shm.hpp"
#include "nao/sim_arm.hpp"
#include "nao/attention_ring.hpp"
#include "nao/controller.hpp"
#include "nao/kinematics.hpp"
#include "nao/lola_backend.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "nao/robot_factory.hpp"
#include "nao/robot_loop.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <iosfwd>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace nao::rt {

/// Result of trying real-time scheduling (SCHED_FIFO + mlockall).
struct RealtimeScheduling {
  bool fifo = false;
  bool locked = false;
  int old_policy = 0;
  int old_priority = 0;
  std::string warning;  ///< one line when something was not permitted
};
RealtimeScheduling enterRealtime();
/// Restores what enterRealtime changed; a second call does nothing.
void leaveRealtime(RealtimeScheduling& s);
/// Sleeps until the absolute CLOCK_MONOTONIC time t_ns (clock_nanosleep TIMER_ABSTIME; resumes
/// after signals). Real-time safe.
void sleepUntilNs(std::int64_t t_ns);

/// Puts a live source's human scale (HumanSource::scaleOfLastFrame) into the run's human
/// kinematics for the update of that frame (setHumanScale: ControllerData, the model stays as
/// configured); scale_m 0 leaves the one in force. A live d_h is not known at configure time
/// (rt_live.hpp). Real-time safe.
template <class Dims>
void applyLiveHumanScale(const LiveHumanScale& scale, ControllerData<Dims>& data) {
  setHumanScale(data, scale.scale_m, scale.hand_m);
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

namespace detail {

/// The run's policy weights: the compiled-in model's views at the generated offsets into
/// .rodata (no lookup, no copy), or a --weights file's tensors copied into storage the weights
/// own and bound by name; then the int8 or packed fp32 copy the run's precision asks for in
/// `copy`: a compiled-in one copied out of .rodata (anonymousCopy), or made from the views.
/// Releases the decoded file copy first (one fp32 copy resident at a time). Configure time:
/// allocates, throws.
template <class Dims>
PolicyWeights<Dims> bindRunWeights(PreparedRun& p, AlignedBytes& copy) {
  PolicyWeights<Dims> weights =
      p.model_bytes != nullptr
          ? bindPolicyWeightsAt<Dims>(p.model_bytes, p.model_offsets, p.model_extents, p.model.header.arch,
                                      p.model.header.conditioning, p.kernel)
          : bindPolicyWeights<Dims>(p.model, p.kernel);
  // The views point into the compiled-in bytes or the weights' storage: the decoded file copy is no longer
  // read, so its memory goes back now, before an int8 or packed copy is made from the views
  // (docs/embedded.md, RSS).
  std::vector<std::uint8_t>().swap(p.model.bytes);
  if (p.precision == WeightPrecision::kInt8) {
    if constexpr (int8Supported<Dims>()) {
      if (quantizedModelBytes(p.model.header.arch) != quantizedPolicyBytes<Dims>())
        throw std::logic_error("nao_rt: the int8 blob of the model is not the compiled layout's size");
      copy = p.int8_bytes != nullptr ? anonymousCopy(p.int8_bytes, quantizedPolicyBytes<Dims>())
                                     : quantizePolicyInt8<Dims>(weights);
      bindQuantizedWeights<Dims>(weights, copy.data.get());
    } else {
      throw std::runtime_error("--precision int8: this architecture has an odd or over-512 input size; int8 "
                               "needs even input sizes up to 512");
    }
  }
  // fp32-packed: the same floats in the kernels' block order, compiled in (nao_codegen
  // --precision fp32-packed) or made at start-up.
  if (p.precision == WeightPrecision::kFp32Packed) {
    if constexpr (packedSupported<Dims>()) {
      if (packedModelBytes(p.model.header.arch) != packedPolicyBytes<Dims>())
        throw std::logic_error("nao_rt: the packed blob of the model is not the compiled layout's size");
      copy = p.packed_bytes != nullptr ? anonymousCopy(p.packed_bytes, packedPolicyBytes<Dims>())
                                       : packPolicyFp32<Dims>(weights);
      bindPackedWeights<Dims>(weights, copy.data.get());
    } else {
      throw std::runtime_error("--precision fp32-packed: this architecture has a matrix the packed layout does "
                               "not take (outputs in multiples of 32, inputs of 16)");
    }
  }
  return weights;
}

/// What the LoLA cycle before a tick's packet warms (LolaParams::before_tick).
template <class Dims>
struct WarmContext {
  const PolicyWeights<Dims>* weights;
  const PolicyWorkspace<Dims>* workspace;
  std::uint64_t sink;
};

/// The robot a run drives (the backend owns its hardware), from --robot (makeRobotBackend):
/// the in-process ODE arm at the run's start, or LoLA through its socket, opened here, with the
/// I/O thread's probe and the warming before each tick's packet. Configure time: allocates,
/// throws.
template <class Dims>
std::unique_ptr<RobotBackend> makeRunRobot(const RunOptions& options, const PreparedRun& p, AllocationProbe* probe,
                                           WarmContext<Dims>& warm) {
  LolaParams lola_params = options.lola;
  // The I/O thread's own count (summary.json lola.io_allocations), not the control thread's.
  lola_params.io_probe = probe != nullptr ? probe->companion() : nullptr;
  if (options.lola_warm && !lola_params.io_thread) {
    lola_params.before_tick = [](void* c) {
      auto* w = static_cast<WarmContext<Dims>*>(c);
      warmPolicy(*w->weights, *w->workspace, w->sink);
    };
    lola_params.before_tick_context = &warm;
  }
  return makeRobotBackend(options.robot, p.arm, p.q_start, options.sim, lola_params);
}

/// The run's attention records and the buffers the loop fills, all allocated before activate.
template <class Dims>
struct RunBuffers {
  RingHolder<RunRing<Dims>> rings;
  std::unique_ptr<RunPayload<Dims>> payload = std::make_unique<RunPayload<Dims>>();
  std::vector<TickRecord> records;
};

/// The ticks from activate to deactivate (no allocation, no I/O, no exception): each tick's
/// human frame, the controller's update (the policy, or `law` in its place), the evaluation
/// target's hand point, the overrun bookkeeping when paced, the attention record into the ring.
/// Returns the ticks done (fewer than p.ticks when the robot stops the run).
template <class Dims>
std::int64_t runTicks(const RunOptions& options, PreparedRun& p, const ControllerModel<Dims>& model,
                      ControllerData<Dims>& data, RobotBackend& robot, ActionLaw* law, bool paced,
                      RunBuffers<Dims>& buffers, LoopTotals& totals) {
  // The evaluation target of a recorded reference (its feature-extracted trajectory).
  const std::vector<JointVector>* target = p.has_targets ? &p.reference->target : nullptr;
  const std::size_t n_targets = target != nullptr ? target->size() : 0;
  const std::int64_t period_ns = static_cast<std::int64_t>(options.controller.period_s * 1e9 + 0.5);
  ArmData kin_ref;
  RunRing<Dims>& ring = buffers.rings.ring();
  std::int64_t next_ns = monotonicNs();
  std::int64_t ticks_done = 0;
  for (std::int64_t t = 0; t < p.ticks && robot.stopReason() == RobotStop::kNone; ++t) {
    if (paced) sleepUntilNs(next_ns);
    const std::size_t i = static_cast<std::size_t>(t);
    const SkeletonFrame* frame = p.human != nullptr ? p.human->frameAt(t) : nullptr;
    if (frame != nullptr) applyLiveHumanScale(p.human->scaleOfLastFrame(), data);
    TickRecord& rec = buffers.records[i];
    rec = law != nullptr ? runControllerTick(model, data, robot, frame, *law) : runControllerTick(model, data, robot, frame);
    // Where the arm should be at the end of the tick: the reference's feature-extracted pose
    // of the next sample (the last one held at the end).
    if (i < n_targets)
      rec.ee_ref = forwardKinematics(p.arm, kin_ref, (*target)[std::min(i + 1, n_targets - 1)]);
    else
      rec.ee_ref.setConstant(std::numeric_limits<double>::quiet_NaN());
    if (paced) {
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
    fillPayload<Dims>(rec, *data.policy, *buffers.payload);
    pushFromRT(ring, *buffers.payload);
    ticks_done = t + 1;
  }
  return ticks_done;
}

}  // namespace detail

/// Runs nao_rt once with the policy compiled as Dims (see the top of this file). Never throws:
/// a problem ends the run with report.status != 0 and report.error set (one line).
/// @param out   the human summary (and the configuration line)
/// @param err   warnings (--realtime not permitted)
/// @param probe allocation counter around activate ... deactivate; nullptr: not counted
/// @param law   an action law in place of the policy (nao/controller.hpp ActionLaw: the
///              evaluation's baselines, run in process by nao_toolchain evaluate; summary.json
///              names it); nullptr: the policy
template <class Dims>
RunReport runController(const RunOptions& options, std::ostream& out, std::ostream& err,
                        AllocationProbe* probe = nullptr, ActionLaw* law = nullptr) {
  RunReport report;
  try {
    // Configure: everything that can fail or allocate.
    if (!isRobotBackendName(options.robot))
      throw UsageError("--robot '" + options.robot + "': expected " + kRobotBackendNames);
    PreparedRun p = prepareRun(options, Dims::arch());
    AlignedBytes copy_storage;  // the int8 or packed copy the run reads (copied or made at start-up)
    PolicyWeights<Dims> weights = detail::bindRunWeights<Dims>(p, copy_storage);
    const PolicyKernel kernel = weights.kernel;
    ControllerParams controller_params = options.controller;
    // The human's scale d_h is calibrated once per reference, as the training data and the
    // evaluation target were retargeted (one scale per demonstration from all its frames:
    // retargetTargets), not re-estimated per frame: per-frame link lengths jitter with
    // the keypoint noise, which moved the hand target, flipped key-pose snaps and left the
    // controller tracking another trajectory than the one it is scored against.
    if (controller_params.human.scale_m <= 0.0 && p.reference != nullptr && p.reference->human.scale_m > 0.0)
      controller_params.human = p.reference->human;
    // A live reference: --human-scale, or each frame's scale from the source (applyLiveHumanScale).
    if (p.live != nullptr && options.human_scale_m > 0.0) controller_params.human.scale_m = options.human_scale_m;
    // The retargeting setting is the model's (spec.retarget, read over options.controller.retarget).
    const ControllerModel<Dims> model =
        configureController(p.arm, p.model_spec, std::move(weights), controller_params);
    detail::WarmContext<Dims> warm{&model.policy, nullptr, 0};
    LoopTotals totals;
    totals.kernel = kernel;
    RealtimeScheduling rt;
    // Left on every way out, an exception included (runController also runs inside tests).
    struct LeaveRealtime {
      RealtimeScheduling& s;
      ~LeaveRealtime() { leaveRealtime(s); }
    } leave_realtime{rt};
    // Before the backend: its I/O thread (--lola-io-thread), started at configure time, inherits
    // the control thread's SCHED_FIFO; mlockall covers the whole process either way.
    if (options.realtime) {
      rt = enterRealtime();
      totals.realtime_scheduling = rt.warning.empty() ? "SCHED_FIFO + mlockall" : rt.warning;
    }
    const std::unique_ptr<RobotBackend> robot = detail::makeRunRobot<Dims>(options, p, probe, warm);
    // LoLA's counters and latencies go into summary.json.
    LolaBackend* const lola = dynamic_cast<LolaBackend*>(robot.get());
    if (lola != nullptr) totals.lola_io_scheduling = lola->ioThreadScheduling();
    // --realtime paces the in-process arm on 100 ms deadlines; a robot whose packets are the
    // clock (LoLA) paces itself, and --realtime only asks for SCHED_FIFO + mlockall.
    const bool paced = options.realtime && !robot->pacesTicks();
    if (options.realtime && !rt.warning.empty())
      err << "nao_rt: warning: " << rt.warning << "; running on " << (paced ? "absolute deadlines" : "the robot's clock")
          << " without it\n";
    auto data = std::make_unique<ControllerData<Dims>>();
    warm.workspace = data->policy.get();
    detail::RunBuffers<Dims> buffers;
    const AttentionDescriptor descriptor = attentionPayloadDescriptor<RunPayload<Dims>>();
    if (options.attention_shm.empty())
      buffers.rings.local = std::make_unique<RunRing<Dims>>(descriptor);
    else
      buffers.rings.shared = std::make_unique<SharedAttentionRing<RunRing<Dims>>>(options.attention_shm, descriptor);
    buffers.records.resize(static_cast<std::size_t>(p.ticks));
    SteadyClock steady;
    ControllerClock& clock = options.clock != nullptr ? *options.clock : steady;

    out << "nao_rt: " << p.description << " -> movement " << p.spec.movement << ", model " << p.model_source << ", " << p.ticks << " ticks ("
        << static_cast<double>(p.ticks) * options.controller.period_s << " s), "
        << (lola != nullptr ? "on LoLA " + lola->socketPath() : paced ? "real time" : "back to back")
        << (lola != nullptr && options.realtime ? " (" + totals.realtime_scheduling + ")" : "") << "\n";
    out.flush();

    // Every page the step reads resident before the loop (a released image's, a --weights
    // copy's): one pass over them, no page fault on the first tick.
    {
      std::uint64_t sink = 0;
      warmPolicy(model.policy, *data->policy, sink);
      warm.sink += sink;
    }
    // The live camera reader thread's allocations from activate to deactivate.
    ThreadAllocationCounter* const reader_counter = p.live != nullptr ? options.reader_allocations : nullptr;
    const std::int64_t reader_allocations0 = reader_counter != nullptr ? reader_counter->count() : 0;
    // The loop: no allocation, no I/O, no exception from here to deactivate.
    if (probe != nullptr) probe->start();
    const std::int64_t wall0 = monotonicNs();
    activateOnRobot(model, *data, *robot, p.q_start, p.movement_index, clock);
    const std::int64_t ticks_done = detail::runTicks(options, p, model, *data, *robot, law, paced, buffers, totals);
    const RobotStop stop = robot->stopReason();
    deactivateOnRobot(model, *data, *robot);
    closeFromRT(buffers.rings.ring());
    totals.wall_s = static_cast<double>(monotonicNs() - wall0) * 1e-9;
    if (probe != nullptr) totals.allocations = probe->stop();
    if (reader_counter != nullptr) totals.reader_allocations = reader_counter->count() - reader_allocations0;
    leaveRealtime(rt);
    buffers.records.resize(static_cast<std::size_t>(ticks_done));
    totals.stop = stop;
    if (data->run_code >= 0)
      totals.run_code = p.model_spec.run_codes[static_cast<std::size_t>(p.movement_index)].names[static_cast<std::size_t>(data->run_code)];
    if (law != nullptr) totals.action_law = law->name();
    if (lola != nullptr) {
      totals.lola = true;
      totals.lola_socket = lola->socketPath();
      totals.lola_counters = lola->counters();
      totals.lola_latency_ns = lola->latenciesNs();
    }

    finishRun(options, p, buffers.records, attentionRingView(buffers.rings.ring()), totals, out, report);
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
