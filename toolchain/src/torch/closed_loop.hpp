// Closed-loop training (docs/autonomous.md "How it is trained"): the net rolled out in
// libtorch the way nao_rt runs it - streamed tick by tick (policy_stream.hpp) through the
// command limiter and the trainer's copy of the arm (arm_copy_torch.hpp) - from training starts,
// perturbed starts and starts between two demonstrations, each with the run code the runtime
// would give it there, and scored tick by tick against the medoid replay from that start: the
// code's demonstration tracked by the gain law through the same arm, which is what evaluation
// compares a run with. The loss is backpropagated through the whole rollout. Offline only.
#pragma once

#include "nao/model_file.hpp"
#include "nao/rollout.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"
#include "run_latent.hpp"
#include "train_data.hpp"
#include "train_select.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace nao::tools {

/// The closed-loop phase of training (TrainOptions::closed_loop).
struct ClosedLoopOptions {
  int epochs = 0;               ///< closed-loop epochs after the teacher-forced ones (0: none)
  double lr = 1e-4;             ///< Adam, a fresh optimiser from the kept teacher-forced weights
  int batch = 16;               ///< rollouts per optimiser step
  int horizon = 30;             ///< ticks rolled out in the first closed-loop epoch
  int horizon_growth = 10;      ///< ticks more in every later epoch, up to the whole run
  double perturb_rad = 0.05;    ///< σ of a perturbed start, per joint
  double grad_clip = 1.0;       ///< the gradient's norm is clipped to this (0: no clip)
  double hand_weight = 1.0;     ///< loss per cm² of hand-point error (beside 1 per joint σ² of angle error)
  double limit_weight = 1.0;    ///< loss per a-σ² of action the command limiter cut
  /// Loss per a-σ² of the action's difference from the gain law's toward the code's demonstration
  /// from the state the run is in (the expert of the target, asked where the net went).
  double action_weight = 1.0;
  /// Rollouts per training demonstration and epoch: its own start, then perturbed starts and
  /// starts between it and another demonstration's, in turn.
  int starts = 3;
  /// Each run's segment starts at a tick of its own (closedLoopRunSegmentStart) instead of one
  /// tick per batch below the batch's shortest run: every tick of every run, to its end, can be
  /// rolled. The batches hold runs of nearby segment starts (a recipe-only option, "closed-loop-whole-runs").
  bool whole_runs = false;
  bool enabled() const { return epochs > 0; }
};

/// One closed-loop rollout and its target.
struct ClosedLoopRun {
  int movement = 0;
  int code = -1;        ///< the run code's demonstration: index into the movement's run codes (runCodeIndex)
  int source = -1;      ///< the training demonstration the start was drawn around (data.demos index)
  int source_code = -1; ///< the same as an index into the movement's run codes
  int kind = 0;         ///< 0: its own start, 1: perturbed, 2: between two demonstrations' starts
  JointVector start = JointVector::Zero();
  int ticks = 0;        ///< length of the run
  std::vector<JointVector> q;          ///< target: the code's demonstration tracked from the start, ticks + 1 entries
  std::vector<JointVector> v;          ///< the arm copy's servo velocity along it, ticks + 1 entries
  std::vector<JointVector> a_applied;  ///< its applied actions, ticks entries
  std::vector<JointVector> f_next;     ///< per tick, the code's demonstration's next pose the gain law aims at (clamped)
  std::vector<Eigen::Vector3d> hand;   ///< its hand points
};

/// What the closed-loop rollouts are made of, built once per training run.
struct ClosedLoopData {
  std::vector<ModelRunCodes> codes;                ///< per movement: the training demonstrations' starts and DTW table
  std::vector<std::vector<int>> code_demo;         ///< [movement][code]: its data.demos index
  std::vector<std::vector<std::size_t>> code_seq;  ///< [movement][code]: its clean rollout in the training tensors
  std::vector<JointEnvelope> envelope;             ///< per movement: the workspace the runtime keeps commands in
  std::vector<ClosedLoopRun> own;                  ///< one per training demonstration: from its own start
};

/// The data for `train_seqs` (the training split's executed sequences, whose clean rollouts give
/// the codes) of `data` (the demonstrations as recorded: their f is what a replay tracks).
/// `codes`: the run codes' names, starts and DTW tables (RunCodeSource), in the order of `code_seq`.
ClosedLoopData closedLoopData(const PolicyData& data, const RunCodeSource& codes, const SimModel& sim, double period_s,
                              double workspace_margin_rad);

/// The run code a rollout of `movement` from `start` (clamped to the limits) takes, drawn around
/// training demonstration `source` (its index among the movement's run codes): the runtime's
/// choice there with `source` left out (runCodeIndex(codes, start, source); a movement of one
/// training demonstration plays its own). An index into the movement's run codes.
int closedLoopCode(const ClosedLoopData& cl, int movement, const JointVector& start, int source);

/// The target of a run of `movement` from `start` for `ticks` ticks, drawn around training
/// demonstration `source` (its index among the movement's run codes): the run code the runtime
/// picks there with `source` left out (runCodeIndex: the runs are to play what a run from a start
/// no training demonstration began at plays) and its demonstration tracked from `start` by the
/// gain law through the arm copy (trackDemo on ArmCopyBackend).
ClosedLoopRun closedLoopTarget(const PolicyData& data, const ClosedLoopData& cl, const SimModel& sim, double period_s,
                               int movement, const JointVector& start, int ticks, int source);

/// A rollout's start, drawn around a training demonstration.
struct ClosedLoopStart {
  int movement = 0;
  int source = -1;       ///< data.demos index of the demonstration it is drawn around
  int source_code = -1;  ///< the same as an index into the movement's run codes
  int kind = 0;          ///< 0: its own start, 1: perturbed, 2: between two demonstrations' starts
  JointVector start = JointVector::Zero();
};

/// The starts of closedLoopEpochRuns without their targets: first every training demonstration's
/// own (cl.own's order), then per demonstration `starts` − 1 more in turn, seeded by (seed,
/// epoch, demonstration).
std::vector<ClosedLoopStart> closedLoopStarts(const ClosedLoopData& cl, int starts, double perturb_rad,
                                              std::uint64_t seed, int epoch);

/// The epoch's rollouts: every training demonstration from its own start, then (starts − 1
/// more) in turn from its start perturbed by N(0, σ²) per joint and from a point between its
/// start and another training demonstration's of the same movement (uniform on the segment;
/// perturbed instead when the movement has one demonstration). Seeded by (seed, epoch, demo).
std::vector<ClosedLoopRun> closedLoopEpochRuns(const PolicyData& data, const ClosedLoopData& cl, const SimModel& sim,
                                               double period_s, const ClosedLoopOptions& o, std::uint64_t seed,
                                               int epoch);

/// The horizon of closed-loop epoch k (1-based): horizon + (k − 1) · horizon_growth ticks.
int closedLoopHorizon(const ClosedLoopOptions& o, int k);

/// Where a batch's segments start: a tick drawn uniformly (seeded by `key`) from 0 .. the shortest
/// run's length − horizon (0 when a run is no longer than the horizon: the runs are rolled out
/// from their starts).
int closedLoopSegmentStart(const std::vector<const ClosedLoopRun*>& runs, int horizon, std::uint64_t key);

/// Whole runs: where run `run`'s segment starts, a tick drawn uniformly (seeded by `key`) from 0 ..
/// its own length − horizon (0 when it is no longer than the horizon).
int closedLoopRunSegmentStart(const ClosedLoopRun& run, int horizon, std::uint64_t key);

/// The loss of rolling `net` out for `runs` over ticks start_tick .. start_tick + horizon − 1
/// (each run's own ticks).
struct ClosedLoopLoss {
  torch::Tensor loss;         ///< summed over the rolled ticks of every run; differentiable
  std::int64_t ticks = 0;     ///< the rolled ticks of every run
  double hand_sse_m2 = 0.0;   ///< Σ over those ticks of the squared hand-point error, m²
  std::vector<double> run_hand_sse_m2;  ///< the same per run
};
/// The loss per rolled tick: the hand point's squared error in cm² times hand_weight, plus each
/// joint's squared error in q-σ, plus limit_weight times the squared action (a-σ) the limiter cut,
/// plus action_weight times the squared difference (a-σ) from the gain law's action from the
/// state reached, g (f_next − q) (the label, no gradient through it). `latent` (nullptr: zero
/// codes) gives each run its code P μ of its code's clean rollout in `train`. The net streams from tick 0 with step rows 0, 1, ...; before start_tick it is fed the
/// target's own states and actions (its caches filled as along the target, no gradient), from
/// start_tick on its actions drive the arm copy (armCopyTick, the movement's envelope) from the
/// target's state at that tick.
ClosedLoopLoss closedLoopLoss(const PolicyNetImpl& net, RunLatentImpl* latent, const SequenceTensors& train,
                              const ClosedLoopData& cl, const SimModel& sim, double period_s,
                              const std::vector<const ClosedLoopRun*>& runs, int start_tick, int horizon,
                              const ClosedLoopOptions& o);
/// The same with a segment start per run (start_ticks[b] for runs[b]): each run rolls its ticks
/// start_ticks[b] .. + horizon − 1 (to its end). All runs stream side by side from tick 0; before
/// its segment a run follows its target's states and actions, its caches filled without
/// gradient, as in the warm-up; at its segment's first tick it starts from the target's state.
/// Equal starts give the single-start loss exactly.
ClosedLoopLoss closedLoopLoss(const PolicyNetImpl& net, RunLatentImpl* latent, const SequenceTensors& train,
                              const ClosedLoopData& cl, const SimModel& sim, double period_s,
                              const std::vector<const ClosedLoopRun*>& runs, const std::vector<int>& start_ticks,
                              int horizon, const ClosedLoopOptions& o);

}  // namespace nao::tools
