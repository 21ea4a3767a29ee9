// The 10 Hz imitation controller: human frame -> human kinematics + scaling ->
// fixed-size LM retargeting (Algorithm 1) -> snap to the model's key pose -> policy ->
// commandFor (rollout.hpp: q_t + a_t within the position and velocity limits) -> record.
//
// The controller never talks to a robot. Its caller reads the arm, hands the measured angles
// to updateController, and writes the returned command (TickRecord::q_cmd) to the arm, as a
// robot framework calls a controller's update between its own read and write
// (docs/embedding.md). nao_backends' runControllerTick (nao/robot_loop.hpp) is that cycle
// for its robots (the ODE arm, LoLA), with finishTick recording what the robot did.
//
// The model contract: configureController(arm, spec, weights) takes what a model.bin tells a run
// (ModelSpec: readModelSpec) and its bound weights (bindPolicyWeights<Dims>(file): they own
// their floats) and builds a ControllerModel that nothing writes afterwards and that depends on
// no file object; everything a run changes is in ControllerData.
//
// Lifecycle: configureController builds everything that allocates (ControllerModel,
// ControllerData); activateController starts a run from the pose the arm is at;
// updateController runs one tick; deactivateController ends the run. Between activate and
// deactivate nothing allocates, blocks, throws or does I/O: in-loop anomalies are fault bits in
// the tick record, counted, each with the fallback documented at ControllerFault.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"
#include "nao/feature_trajectory.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/kinematics.hpp"
#include "nao/model_spec.hpp"
#include "nao/policy.hpp"
#include "nao/retarget.hpp"
#include "nao/rollout.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

namespace nao {

/// Fault bits of a tick (ticks.csv column `fault`). Bits 0-7, 14 and 15 come from the tick itself
/// and never stop the loop; bits 8-13 come from the robot (finishTick: LoLA's; the ODE arm
/// raises none).
enum ControllerFault : std::uint32_t {
  /// No usable human arm this tick (no frame, torso/arm keypoints missing) for longer than the
  /// bridge (kFaultHumanBridged): the last reference is held.
  kFaultNoHuman = 1u << 0,
  /// No usable human for longer than ControllerParams::no_human_timeout_s: the policy is
  /// bypassed and the arm returns to the home pose at half its velocity limits.
  kFaultHumanTimeout = 1u << 1,
  /// NaN/Inf among the keypoints the arm needs (also sets kFaultNoHuman, or kFaultHumanBridged
  /// within the bridge).
  kFaultNonFiniteKeypoints = 1u << 2,
  /// Algorithm 1 hit an iteration cap: the reference is its best feasible pose (see
  /// kFaultRetargetFallback), never worse than the clamped human angles.
  kFaultIkNotConverged = 1u << 3,
  /// The tick's action (the policy's, or an ActionLaw's) had a NaN/Inf: the command limiter
  /// holds the arm where it is (a = 0; rollout.hpp).
  kFaultPolicyNonFinite = 1u << 4,
  /// The tick's work took longer than the period (counted; the loop stays on the grid).
  kFaultOverrun = 1u << 5,
  /// Informational: the command was cut to the position or velocity limits.
  kFaultCommandLimited = 1u << 6,
  /// The retargeting solve put the hand farther from its target than the clamped human angles
  /// do: the reference is the clamped human angles this tick (retarget.hpp, kRetargetFallback).
  kFaultRetargetFallback = 1u << 7,
  /// The robot's socket closed, or no packet came for LolaParams::link_lost_cycles: the backend
  /// stops (safe stop as far as the link allows) and the run ends with a non-zero exit status.
  kFaultRobotLinkLost = 1u << 8,
  /// No sensor packet for more than 2 cycles (24 ms): counted; the run goes on when packets
  /// resume (the controller's clock is the packet count, so the tick stretches).
  kFaultRobotPacketGap = 1u << 9,
  /// A packet that is not MessagePack, or lacks a key, or has an array of the wrong length:
  /// counted and skipped (not answered, no cycle counted); the last good measurement is kept.
  kFaultRobotMalformedPacket = 1u << 10,
  /// A joint's temperature is above LolaParams::hot_c: that joint's stiffness is scaled by
  /// LolaParams::hot_stiffness_scale until it cools below the threshold.
  kFaultJointHot = 1u << 11,
  /// A right-arm joint measured farther than LolaParams::tracking_error_rad from its previous
  /// cycle's command: counted (the arm is not pushed harder).
  kFaultTrackingError = 1u << 12,
  /// The backend ended the run early (link lost, SIGINT/SIGTERM): hold, stiffness ramped to 0.
  kFaultSafeStop = 1u << 13,
  /// A short detector gap: no usable human this tick, but one within the last
  /// ControllerParams::human_bridge_ticks ticks. The last reference is held (as for
  /// kFaultNoHuman, which this tick does not set).
  kFaultHumanBridged = 1u << 14,
  /// Autonomous mode: the policy's command left the demonstrated workspace (the movement's key
  /// poses' joint range ± ControllerParams::workspace_margin_rad) and was cut to it.
  kFaultOutsideWorkspace = 1u << 15,
};
inline constexpr int kNumControllerFaults = 16;
inline constexpr std::array<const char*, kNumControllerFaults> kControllerFaultNames = {
    "no_human", "human_timeout", "nonfinite_keypoints", "ik_not_converged", "policy_nonfinite", "overrun",
    "command_limited", "retarget_fallback", "robot_link_lost", "robot_packet_gap", "robot_malformed_packet",
    "joint_hot", "tracking_error", "safe_stop", "human_bridged", "outside_workspace"};

/// Injected monotonic clock: the real one reads CLOCK_MONOTONIC, tests drive time.
struct ControllerClock {
  virtual ~ControllerClock() = default;
  /// Nanoseconds on a monotonic scale. Real-time safe.
  virtual std::int64_t nowNs() = 0;
};

/// CLOCK_MONOTONIC.
/// CLOCK_MONOTONIC now, ns. Real-time safe (the one reading of the real clock: SteadyClock, the
/// --realtime pacing, the LoLA backend and nao_lola_sim use it).
std::int64_t monotonicNs();

struct SteadyClock final : ControllerClock {
  std::int64_t nowNs() override;
};

struct ControllerParams {
  double period_s = 0.1;             ///< control period (10 Hz)
  double no_human_timeout_s = 3.0;   ///< hold the last reference this long, then go home
  /// Detector gaps of at most this many ticks after a usable human are bridged
  /// (kFaultHumanBridged) instead of counted as kFaultNoHuman; 0: never.
  int human_bridge_ticks = 2;
  /// NAO's rest pose (arm down, elbow slightly bent), rad; clamped to the limits.
  JointVector home = (JointVector() << 1.40, -0.20, 1.20, 0.50, 0.00).finished();
  RetargetParams retarget;
  HumanKinematicsConfig human;       ///< scale_m > 0 fixes the human scale d_h (else per frame)
  /// Pole of the online feature-extracted reference the policy is fed in reference mode (the
  /// blend of the snapped key poses, as the training data's f; must equal the data's).
  double feature_pole = kFeatureBlendPole;
  /// Autonomous mode: commands stay within the movement's demonstrated joint range widened by
  /// this margin (rad): where no demonstration went, the arm does not go (kFaultOutsideWorkspace
  /// counts the ticks cut). 0.09: the arm's measured angles then stay within 0.1 rad of the range
  /// (the servo settles up to ~2 mrad past a command). Negative: the arm's limits alone.
  double workspace_margin_rad = 0.09;
};

/// One tick as recorded (ticks.csv; angles rad, positions m in the torso frame).
struct TickRecord {
  std::int64_t tick = 0;
  double t_s = 0.0;                    ///< tick start time on the grid
  JointVector q_ref = JointVector::Zero();   ///< retargeted reference (q_r of Algorithm 1)
  JointVector r = JointVector::Zero();       ///< snapped key pose fed to the policy
  JointVector a = JointVector::Zero();       ///< policy action a_t (0 when bypassed)
  /// The network's part of a (the decoded chunk or bin + offset, before any law the model adds);
  /// NaN on ticks the policy did not run (return home, evaluation laws)
  JointVector a_net = JointVector::Constant(std::numeric_limits<double>::quiet_NaN());
  JointVector q_cmd = JointVector::Zero();   ///< command sent to the servos
  /// Measured joint angles at the end of the tick (LoLA: as measured), from finishTick; until
  /// then (updateController alone) the angles the tick started from.
  JointVector q = JointVector::Zero();
  /// Hand point of q (finishTick; NaN until then).
  Eigen::Vector3d ee = Eigen::Vector3d::Zero();
  Eigen::Vector3d ee_ref = Eigen::Vector3d::Constant(std::nan(""));  ///< evaluation target (driver fills)
  std::array<float, kNumJoints> att{};   ///< per-body-part norm-based attention score, summed over the window
  std::array<float, kNumJoints> attm{};  ///< per-body-part raw cross-attention mass (sums to 1)
  std::uint32_t fault = 0;             ///< ControllerFault bits
  int key_pose = 0;                    ///< index of r among the movement's key poses
  /// Stage timings; sim_us is the robot's work (finishTick; 0 until then), tick_us the whole
  /// tick, both without the time spent waiting for the robot (LoLA's packet clock).
  double tick_us = 0.0, retarget_us = 0.0, policy_us = 0.0, sim_us = 0.0;
};

/// The immutable part: arm, policy weights, parameters, what the model.bin tells a run. Built by
/// configureController and never written afterwards (only read through const references); it
/// shares ownership of the floats its weights view (PolicyWeights::storage) when they were
/// bound from a ModelFile, so it outlives the file it was read from.
template <class Dims>
struct ControllerModel {
  ArmModel arm;
  PolicyWeights<Dims> policy;
  ControllerParams params;
  double d_r_m = 0.0;             ///< robot scale (paper eq. 1)
  JointVector home = JointVector::Zero();  ///< params.home clamped
  /// Per movement, the autonomous workspace envelope (empty: none, reference mode or a
  /// negative margin).
  std::vector<JointEnvelope> workspace;
  /// The model's movement names, starts, demonstrated workspace, run codes (per movement, the
  /// codes a run chooses from at activate; empty: the zero code), retargeting setting (the one
  /// params.retarget holds), split and data fingerprint.
  ModelSpec spec;
};

/// Everything a tick writes. Built at configure time.
template <class Dims>
struct ControllerData {
  CommandStep step;               ///< the last tick's command (commandFor)
  ArmData kin;
  HumanArmData human;
  RetargetData retarget;
  std::unique_ptr<PolicyWorkspace<Dims>> policy = makePolicyWorkspace<Dims>();
  ControllerClock* clock = nullptr;
  int movement = 0;
  /// The run code in use: index into model.spec.run_codes[movement] (-1: the zero code).
  int run_code = -1;
  /// The run's human kinematics: model.params.human from activate on, a live source's human
  /// scale on top (setHumanScale).
  HumanKinematicsConfig human_config;
  bool active = false;
  std::int64_t tick = 0;
  std::int64_t last_human_tick = -1;     ///< last tick with a usable human (-1: none yet)
  JointVector q_ref = JointVector::Zero();
  JointVector a_prev = JointVector::Zero();
  /// The online feature-extracted trajectory of the snapped key poses: f(t) and v(t−1); the
  /// reference-mode policy's input r is f(t+1) (docs/policy.md "Data").
  JointVector feature_f = JointVector::Zero(), feature_v = JointVector::Zero();
  bool feature_started = false;
  std::array<std::int64_t, kNumControllerFaults> fault_counts{};
  TickRecord record;                     ///< the last tick
  /// The last tick's clock readings at its start and at the end of updateController (finishTick
  /// adds the robot's time to them).
  std::int64_t tick_start_ns = 0, update_end_ns = 0;
};

/// Per movement, the demonstrated joint range widened by `margin_rad`: the workspace an
/// autonomous run's commands stay in (configure time, allocates). The range is the model's
/// "workspace" metadata (`demonstrated`, one entry per movement); a model without it falls back
/// to its key poses' range.
template <class Dims>
std::vector<JointEnvelope> workspaceEnvelopes(const PolicyWeights<Dims>& policy, double margin_rad,
                                              const std::vector<ModelWorkspace>& demonstrated = {}) {
  std::vector<JointEnvelope> out;
  if (static_cast<int>(demonstrated.size()) == policy.movements) {
    for (const ModelWorkspace& w : demonstrated) out.push_back(widenedEnvelope(w.lo, w.hi, margin_rad));
    return out;
  }
  const int K = policy.clusters;
  for (int mv = 0; mv < policy.movements; ++mv) {
    JointEnvelope e;
    for (int j = 0; j < kNumJoints; ++j) e.lo[j] = e.hi[j] = static_cast<double>(policy.centroids(j, mv * K));
    for (int k = 1; k < K; ++k)
      for (int j = 0; j < kNumJoints; ++j) {
        const double c = static_cast<double>(policy.centroids(j, mv * K + k));
        e.lo[j] = std::min(e.lo[j], c);
        e.hi[j] = std::max(e.hi[j], c);
      }
    e.lo.array() -= margin_rad;
    e.hi.array() += margin_rad;
    out.push_back(e);
  }
  return out;
}

/// Builds the model (configure time, allocates; throws std::invalid_argument for bad
/// parameters) from what a model.bin tells a run and its bound weights:
///   const ModelFile file = readModelFile(path);  // checkJointsMatch(file, arm, path) too
///   const auto model = configureController(arm, readModelSpec(file.header, {}, path),
///                                          bindPolicyWeights<Dims>(file));
/// `spec` (readModelSpec) gives the retargeting setting (params.retarget is replaced by
/// spec.retarget), the demonstrated workspace an autonomous model's envelope widens (empty: its
/// key poses') and the run codes (empty: none; else one entry per movement of d_model floats).
/// `policy` must be bound; the arm is the one the policy was checked against.
template <class Dims>
ControllerModel<Dims> configureController(const ArmModel& arm, ModelSpec spec, PolicyWeights<Dims> policy,
                                          ControllerParams params = {}) {
  if (!(params.period_s > 0.0)) throw std::invalid_argument("controller: period must be positive");
  if (!(params.no_human_timeout_s >= 0.0)) throw std::invalid_argument("controller: negative no-human timeout");
  if (params.human_bridge_ticks < 0) throw std::invalid_argument("controller: negative human bridge");
  params.retarget = spec.retarget;
  const std::vector<ModelRunCodes>& run_codes = spec.run_codes;
  if (!run_codes.empty()) {
    if (policy.conditioning != Conditioning::kAutonomous)
      throw std::invalid_argument("controller: run codes are for autonomous-mode models");
    if (static_cast<int>(run_codes.size()) != policy.movements)
      throw std::invalid_argument("controller: run codes for another number of movements than the model's");
    for (const ModelRunCodes& c : run_codes)
      if (c.d != Dims::kDModel || c.code.size() != c.size() * static_cast<std::size_t>(c.d))
        throw std::invalid_argument("controller: run codes of another width than the model's d_model");
  }
  ControllerModel<Dims> m{arm, std::move(policy), params, robotScale(arm), clampToLimits(arm, params.home), {}, {}};
  if (m.policy.conditioning == Conditioning::kAutonomous && params.workspace_margin_rad >= 0.0)
    m.workspace = workspaceEnvelopes(m.policy, params.workspace_margin_rad, spec.workspace);
  m.spec = std::move(spec);
  return m;
}

/// The same for weights that come without a model.bin (tests, generated weights): the pieces of
/// a ModelSpec given one by one, the retargeting setting params.retarget's.
template <class Dims>
ControllerModel<Dims> configureController(const ArmModel& arm, const PolicyWeights<Dims>& policy,
                                          const ControllerParams& params,
                                          const std::vector<ModelWorkspace>& demonstrated = {},
                                          const std::vector<ModelRunCodes>& run_codes = {}) {
  ModelSpec spec;
  spec.workspace = demonstrated;
  spec.run_codes = run_codes;
  spec.retarget = params.retarget;
  return configureController(arm, std::move(spec), policy, params);
}

namespace detail {
inline double microseconds(std::int64_t from_ns, std::int64_t to_ns) {
  return static_cast<double>(to_ns - from_ns) * 1e-3;
}
}  // namespace detail

/// Starts a run from q, the pose the arm is at (rad: the caller brought its robot to the start
/// pose, clamped to the limits, and passes what the robot reports): resets the retargeting warm
/// start to it, clears the counters and the previous action, and selects `movement` (index into
/// the model's movement names), the clock and, for a model with run codes, the code of the run
/// from that start (runCodeIndex). Real-time safe (no allocation): may be called again to restart.
template <class Dims>
void activateController(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const JointVector& q,
                        int movement, ControllerClock& clock) {
  resetHumanArm(data.human);
  resetRetarget(model.arm, data.retarget, q);
  data.clock = &clock;
  data.movement = movement;
  data.tick = 0;
  data.last_human_tick = -1;
  data.q_ref = q;
  data.a_prev.setZero();
  data.feature_f = q;
  data.feature_v.setZero();
  data.feature_started = false;
  resetPolicyStream(*data.policy);  // a new rollout: the policy's window starts empty
  setPolicyRunCode(*data.policy, runCode(model.spec.run_codes, movement, q, &data.run_code));
  data.human_config = model.params.human;
  data.fault_counts.fill(0);
  data.record = TickRecord{};
  data.active = true;
}

/// What a tick's action law reads (rad, joint order), formed after the tick's reference stage.
struct ActionInput {
  JointVector q = JointVector::Zero();         ///< measured at the tick's start
  JointVector a_prev = JointVector::Zero();    ///< the action applied last tick, a(t−1)
  JointVector key_pose = JointVector::Zero();  ///< r: the key pose the reference snapped to
  JointVector target = JointVector::Zero();    ///< f(t+1) within the limits: the feature-extracted target
  std::int64_t tick = 0;
};

/// What acts in a tick in place of the policy (updateController's second form): the
/// evaluation's baselines (nao_toolchain evaluate) and the tests' fault injection. The deployed
/// controller's action is the policy's (policyAction). The tick's other stages - reference,
/// command limits, record - stay the controller's own.
struct ActionLaw {
  virtual ~ActionLaw() = default;
  /// A short name for the run's summary, e.g. "blend law".
  virtual const char* name() const = 0;
  /// a(t), rad per tick, joint order (non-finite: the arm holds, kFaultPolicyNonFinite).
  /// Called inside the tick: real-time safe, no exception.
  virtual JointVector action(const ActionInput& in) = 0;
};

/// The policy's action for the tick: stepPolicy on q, a(t−1) and target − q (docs/policy.md),
/// with its network part and attention into data.record. Real-time safe.
template <class Dims>
JointVector policyAction(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const ActionInput& in) {
  TickRecord& rec = data.record;
  PolicyInput p;
  p.q = in.q.cast<float>();
  p.a_prev = in.a_prev.cast<float>();
  p.r = (in.target - in.q).cast<float>();
  p.movement = data.movement;
  p.step = static_cast<int>(std::min<std::int64_t>(in.tick, model.policy.max_steps - 1));
  const JointVector a = stepPolicy(model.policy, *data.policy, p).template cast<double>();
  rec.a_net = data.policy->net_action.template cast<double>();
  for (int j = 0; j < kNumJoints; ++j) {
    rec.att[static_cast<std::size_t>(j)] = data.policy->score[j];
    rec.attm[static_cast<std::size_t>(j)] = data.policy->mass[j];
  }
  return a;
}

namespace detail {

/// Stage 1 (reference mode): human kinematics -> scaled hand target -> Algorithm 1, into
/// data.q_ref, and the human's fault bits (bridged gap, lost, timed out) into data.record.
template <class Dims>
void referenceStage(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const SkeletonFrame* frame) {
  TickRecord& rec = data.record;
  const ControllerParams& p = model.params;
  bool have_human = false;
  if (frame != nullptr) {
    humanArmKinematics(data.human_config, data.human, *frame);
    if (data.human.flags & kHumanNotFinite) rec.fault |= kFaultNonFiniteKeypoints;
    have_human = data.human.valid;
  }
  if (have_human) {
    const Eigen::Vector3d p_target = model.arm.p_PJ[0] + scaleHumanEndpoint(model.d_r_m, data.human.d_h_m,
                                                                             data.human.p_SH_T);
    const JointVector q_target = data.human.q.template head<kNumJoints>();
    const RetargetResult& r = solveRetarget(model.arm, p.retarget, data.retarget, p_target, q_target);
    // The caps of the solve that made q_r.
    const std::uint32_t kCaps = p.retarget.priority == RetargetPriority::kHand
                                    ? std::uint32_t{kRetargetXCapHit}
                                    : std::uint32_t{kRetargetQCapHit | kRetargetInnerCapHit};
    if (r.flags & kRetargetBadInput) {
      have_human = false;
    } else {
      // A capped solve still gives the best feasible pose (q_r never does worse than clamping).
      if (r.flags & kCaps) rec.fault |= kFaultIkNotConverged;
      if (r.flags & kRetargetFallback) rec.fault |= kFaultRetargetFallback;
      data.q_ref = r.q_r;
    }
  }
  if (have_human) {
    data.last_human_tick = data.tick;
  } else if (data.last_human_tick >= 0 && data.tick - data.last_human_tick <= p.human_bridge_ticks) {
    // A short detector gap: the held reference bridges it.
    rec.fault |= kFaultHumanBridged;
  } else {
    rec.fault |= kFaultNoHuman;
    const double since_s = static_cast<double>(data.tick - data.last_human_tick) * p.period_s;
    if (since_s > p.no_human_timeout_s) rec.fault |= kFaultHumanTimeout;
  }
}

/// Stage 2: snap q_ref to the model's key pose (rec.key_pose, rec.r) and advance the online
/// feature-extracted trajectory toward it; returns what an action law reads at the measured q.
template <class Dims>
ActionInput actionInput(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const JointVector& q) {
  TickRecord& rec = data.record;
  rec.key_pose = snapToCentroid(model.policy, data.movement, data.q_ref);
  rec.r = centroid(model.policy, data.movement, rec.key_pose).template cast<double>();
  // The feature-extracted target of this tick, f(t+1): the blend toward the key pose in force,
  // started at rest on the first key pose (as featureTrajectory).
  if (!data.feature_started) {
    data.feature_f = rec.r;
    data.feature_v.setZero();
    data.feature_started = true;
  }
  const double pole = model.params.feature_pole;
  data.feature_v = pole * pole * data.feature_v + (1.0 - pole) * (1.0 - pole) * (rec.r - data.feature_f);
  data.feature_f += data.feature_v;
  ActionInput in;
  in.q = q;
  in.a_prev = data.a_prev;
  in.key_pose = rec.r;
  in.target = clampToLimits(model.arm, data.feature_f);
  in.tick = data.tick;
  return in;
}

/// Toward home at half the velocity limits: once the human is gone past the timeout no action
/// law's input is trustworthy any more.
template <class Dims>
JointVector homeAction(const ControllerModel<Dims>& model, const JointVector& q) {
  JointVector a;
  for (int j = 0; j < kNumJoints; ++j) {
    const double step = 0.5 * model.arm.v_max[j] * model.params.period_s;
    a[j] = std::clamp(model.home[j] - q[j], -step, step);
  }
  return a;
}

/// Stage 4: command q + a inside the position limits and what the servos can do in one period
/// (a non-finite action holds): the record's command and action.
template <class Dims>
void commandStage(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const JointVector& q,
                  const JointVector& a) {
  TickRecord& rec = data.record;
  const JointEnvelope* envelope =
      model.workspace.empty() ? nullptr : &model.workspace[static_cast<std::size_t>(data.movement)];
  data.step = commandFor(model.arm, model.params.period_s, q, a, envelope);
  const CommandStep& step = data.step;
  if (step.limit & kCommandNonFinite) rec.fault |= kFaultPolicyNonFinite;
  if (step.limit & kCommandClamped) rec.fault |= kFaultCommandLimited;
  if (step.limit & kCommandEnveloped) rec.fault |= kFaultOutsideWorkspace;
  rec.a = step.a;
  rec.q_cmd = step.q_cmd;
  rec.q_ref = data.q_ref;
  data.a_prev = step.a_applied;  // the action as applied is the next tick's a(t-1)
  rec.q = q;
  rec.ee.setConstant(std::numeric_limits<double>::quiet_NaN());
}

/// Counts the fault bits of `bits` (ControllerFault) once each.
template <class Dims>
void countFaults(ControllerData<Dims>& data, std::uint32_t bits) {
  for (int b = 0; b < kNumControllerFaults; ++b)
    if (bits & (1u << b)) ++data.fault_counts[static_cast<std::size_t>(b)];
}

/// One tick at the measured q with `act(const ActionInput&)` as its action law, timed on the
/// data's clock.
template <class Dims, class Act>
const TickRecord& tick(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const JointVector& q,
                       const SkeletonFrame* frame, Act&& act) {
  TickRecord& rec = data.record;
  const ControllerParams& p = model.params;
  const std::int64_t t0 = data.clock->nowNs();
  rec.tick = data.tick;
  rec.t_s = static_cast<double>(data.tick) * p.period_s;
  rec.fault = 0;
  rec.a.setZero();
  rec.a_net.setConstant(std::numeric_limits<double>::quiet_NaN());
  if (model.policy.conditioning != Conditioning::kAutonomous) referenceStage(model, data, frame);
  const std::int64_t t1 = data.clock->nowNs();

  const ActionInput in = actionInput(model, data, q);
  const JointVector a = (rec.fault & kFaultHumanTimeout) ? homeAction(model, in.q) : act(in);
  const std::int64_t t2 = data.clock->nowNs();

  commandStage(model, data, q, a);
  const std::int64_t t3 = data.clock->nowNs();
  data.tick_start_ns = t0;
  data.update_end_ns = t3;
  rec.retarget_us = microseconds(t0, t1);
  rec.policy_us = microseconds(t1, t2);
  rec.sim_us = 0.0;
  rec.tick_us = microseconds(t0, t3);
  if (rec.tick_us > p.period_s * 1e6) rec.fault |= kFaultOverrun;
  countFaults(data, rec.fault);
  ++data.tick;
  return rec;
}

}  // namespace detail

/// One 100 ms tick: (1) reference: human frame -> retarget (reference mode), (2) snap to the
/// key pose, feature-extracted target, (3) the policy's action (toward home once the human is
/// gone past the timeout), (4) the command within the limits. `q` is the arm's measured joint
/// angles now (rad); `frame` is the human skeleton of this tick in the world frame (nullptr: no
/// human detected); autonomous-mode models ignore it. Returns data.record: the command to write
/// to the arm for the next period is its q_cmd, the attention its att/attm.
/// No robot, no I/O: real-time safe (no allocation, no exception).
template <class Dims>
const TickRecord& updateController(const ControllerModel<Dims>& model, ControllerData<Dims>& data,
                                   const JointVector& q, const SkeletonFrame* frame) {
  return detail::tick(model, data, q, frame,
                      [&](const ActionInput& in) { return policyAction(model, data, in); });
}

/// The same tick with `law`'s action in place of the policy's (an evaluation's baseline, a
/// test's fault injection): the attention columns stay 0 and a_net NaN unless the law runs
/// the policy itself (policyAction). Real-time safe if `law` is.
template <class Dims>
const TickRecord& updateController(const ControllerModel<Dims>& model, ControllerData<Dims>& data,
                                   const JointVector& q, const SkeletonFrame* frame, ActionLaw& law) {
  return detail::tick(model, data, q, frame, [&](const ActionInput& in) { return law.action(in); });
}

/// After the arm ran the last tick's command for one period: its measured angles at the end
/// (rad), the fault bits it raised (ControllerFault, bits 8-13) and the part of its time spent
/// waiting for the robot (ns, LoLA's packet clock; left out of the timings), into the tick's
/// record (q, ee, fault, sim_us, tick_us; the overrun check on the whole tick) and the fault
/// counts. Optional for a caller that keeps its own record. Real-time safe.
template <class Dims>
const TickRecord& finishTick(const ControllerModel<Dims>& model, ControllerData<Dims>& data, const JointVector& q_end,
                             std::uint32_t robot_faults, std::int64_t robot_wait_ns) {
  TickRecord& rec = data.record;
  const std::uint32_t before = rec.fault;
  rec.q = q_end;
  rec.fault |= robot_faults;
  rec.ee = forwardKinematics(model.arm, data.kin, rec.q);
  const std::int64_t t_end = data.clock->nowNs() - robot_wait_ns;
  rec.sim_us = detail::microseconds(data.update_end_ns, t_end);
  rec.tick_us = detail::microseconds(data.tick_start_ns, t_end);
  if (rec.tick_us > model.params.period_s * 1e6) rec.fault |= kFaultOverrun;
  detail::countFaults(data, rec.fault & ~before);
  return rec;
}

/// A human scale measured live (a camera source's estimate, not known at configure time) for
/// the updates from now on: d_h `scale_m` and the hand segment `hand_m` (m; 0: the per-frame
/// rule); scale_m <= 0 leaves the one in force. Per run: activateController starts from the
/// model's. Real-time safe.
template <class Dims>
void setHumanScale(ControllerData<Dims>& data, double scale_m, double hand_m) {
  if (scale_m > 0.0) {
    data.human_config.scale_m = scale_m;
    data.human_config.hand_length_m = hand_m;
  }
}

/// Ends the run (the caller then has its arm hold where it is: a real robot ramps its stiffness
/// to 0). Real-time safe.
template <class Dims>
void deactivateController(const ControllerModel<Dims>& model, ControllerData<Dims>& data) {
  (void)model;
  data.active = false;
}

}  // namespace nao
