// Training the policy (docs/policy.md, docs/training.md): seeded, one thread per rank,
// deterministic for a fixed world size; data-parallel over a Gloo process group; the epoch kept
// by its validation loss or by its autonomous rollouts; checkpoints and resume; export to
// model.bin and a model card. Offline only (libtorch).
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy_config.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "closed_loop.hpp"
#include "data_parallel.hpp"
#include "policy_torch.hpp"
#include "train_data.hpp"

#include <array>
#include <cstdint>
#include <limits>
#include <ostream>
#include <string>
#include <vector>

namespace nao::tools {

/// Sequences (whole executed rollouts) per optimiser step: a global batch, sliced among the ranks.
inline constexpr int kTrainBatch = 2;

struct TrainOptions {
  std::string config_name = "paper";  ///< recorded in the metadata ("paper" | "small" | ...)
  PolicyArch arch = paperArch();      ///< movements and clusters must match the data
  Conditioning conditioning = Conditioning::kReference;
  std::uint64_t seed = 1;             ///< weights, split and batch order
  int max_epochs = 200;               ///< iteration cap; early stopping usually ends sooner
  int patience = 10;                  ///< epochs without a new best before stopping
  double val_fraction = 0.2;          ///< of each movement's demonstrations
  double lr = 6e-5;                   ///< Adam
  ExecutionOptions execution;         ///< how the demonstrations are executed and labelled
  DistOptions dist;                   ///< world size 1: this process alone, the single-process loop
  std::string checkpoint;             ///< if set, rank 0 writes the state here after every epoch
  /// If set, a directory where the executed demonstrations are kept, one file per (data, split,
  /// execution options, seed, conditioning): a run of other head or training options on the same
  /// data reads them instead of executing again (the bytes are the same either way).
  std::string execution_cache;
  std::string resume;                 ///< if set, continue from this checkpoint (any world size)
  int max_batches = 0;                ///< > 0: each epoch stops after this many global batches (timing)
  bool live_progress = false;         ///< rank 0 also redraws a '\r' line during the epoch (terminals)
  /// Model selection on rollouts (autonomous mode, paper §4.1): after every epoch the net is
  /// rolled out on the simulated arm from each validation demonstration's start (the runtime's
  /// streaming inference, no human input) and scored (RolloutScore); the exported epoch is the
  /// one that makes the most movements, then the lowest DTW (betterEpoch). Patience counts on it too.
  bool select_by_rollout = false;
  /// With rollout selection and run codes: the speed bar of a made movement on each run's speed
  /// over its medoid replay's (what it plays, from its start) instead of over the validation
  /// demonstrations' median (a recipe-only option, "select-speed": "replay").
  bool select_speed_vs_replay = false;
  /// False: the net does not see the previous action a(t-1) (its input weights, the encoder's
  /// a-feature row and the decoder's action embedding, are held at zero), only q over the window.
  /// A policy fed its own last action can learn to copy it, and in closed loop its errors then
  /// persist instead of being corrected (behaviour cloning's copycat problem).
  bool previous_action = true;
  /// K > 0: a per-run latent of K dimensions (RunLatent, training only; z = 0 at run time) with
  /// `latent_kl` × its KL divergence per tick in the loss.
  int latent_dims = 0;
  double latent_kl = 1e-2;
  /// D > 0: the weights scored, kept and written are an exponential moving average of the
  /// trained ones, updated after every optimiser step with decay min(D, (1 + n) / (10 + n)) at
  /// step n; the optimiser trains the raw weights. 0: no average.
  double ema_decay = 0.0;
  /// Autonomous: after the max_epochs teacher-forced epochs (all of them: patience then counts
  /// in this phase only), closed-loop epochs from the kept weights (closed_loop.hpp).
  ClosedLoopOptions closed_loop;
};

/// How the rollouts of one movement went (train_select.hpp): medians over its validation
/// demonstrations' starts.
struct MovementScore {
  double dtw_m = std::numeric_limits<double>::quiet_NaN();  ///< hand-path DTW to the nearest validation demonstration
  double speed_ratio = std::numeric_limits<double>::quiet_NaN();  ///< middle-phase RMS hand speed, runs / demonstrations
  double loops_run = std::numeric_limits<double>::quiet_NaN();    ///< loops drawn in the middle stretch
  double loops_demo = std::numeric_limits<double>::quiet_NaN();
  double range_excess_rad = std::numeric_limits<double>::quiet_NaN();  ///< worst excursion beyond the demonstrations' joint range
  /// With run codes: hand-path DTW to the demonstration whose code the run takes
  double code_fidelity_m = std::numeric_limits<double>::quiet_NaN();
  /// TrainOptions::select_speed_vs_replay: per run its speed over its medoid replay's, the median
  double speed_vs_replay = std::numeric_limits<double>::quiet_NaN();
};

struct EpochStats {
  int epoch = 0;             ///< 1-based
  double train_loss = 0.0;   ///< mean training loss per tick over the epoch's batches (closed loop: its own loss)
  /// A closed-loop epoch: the RMS hand-point error of its rollouts against their targets, m
  /// (NaN for a teacher-forced epoch; not kept by checkpoints).
  double closed_loop_hand_rms_m = std::numeric_limits<double>::quiet_NaN();
  /// The same per kind of start: own, perturbed, between two demonstrations' (ClosedLoopRun::kind).
  std::array<double, 3> closed_loop_kind_rms_m = {std::numeric_limits<double>::quiet_NaN(),
                                                  std::numeric_limits<double>::quiet_NaN(),
                                                  std::numeric_limits<double>::quiet_NaN()};
  double val_loss = 0.0;     ///< the same on the validation split after the epoch
  double val_mse_rad2 = 0.0; ///< the executed action's one-step MSE on the validation split
  double seconds = 0.0;      ///< wall time of the epoch (never written to model.bin)
  std::size_t samples = 0;   ///< training samples of the epoch, all ranks together
  /// TrainOptions::select_by_rollout: the mean over movements of the median DTW, and per movement
  /// the scores (not kept by checkpoints); NaN / empty when off.
  double rollout_dtw_m = std::numeric_limits<double>::quiet_NaN();
  /// Every movement made: speed ratio in 0.7-1.3, loops within ±1 of the demonstrations', joint
  /// range exceeded by ≤ 0.1 rad and DTW under twice the demonstrations' nearest-neighbour DTW.
  /// With run codes: the mean over movements of the median code fidelity (NaN: none; not kept by checkpoints).
  double code_fidelity_m = std::numeric_limits<double>::quiet_NaN();
  bool makes_movement = false;
  int movements_made = 0;  ///< movements whose runs meet those bars
  std::vector<MovementScore> rollouts;
};

struct TrainResult {
  PolicyNet net{nullptr};       ///< the kept weights, norm.*, centroids and law set
  PolicySplit split;
  NormStats stats;
  std::uint64_t fingerprint = 0;
  std::size_t train_samples = 0, val_samples = 0;  ///< ticks
  std::size_t train_sequences = 0;
  double expert_worst_miss_rad = 0.0;  ///< largest end-of-tick miss of the expert (clean rollouts)
  double execution_seconds = 0.0;      ///< wall time of executing the rollouts
  double law_gain = 0.0;               ///< law.gain of the exported model
  std::vector<EpochStats> history;
  int best_epoch = 0;           ///< 1-based epoch whose weights were kept
  SplitLoss train, val;         ///< of the kept weights
  Baselines train_baselines, val_baselines;  ///< rad^2
  double seconds = 0.0;         ///< total wall time
  int world_size = 1;           ///< ranks that trained it
  int threads_per_rank = 1;     ///< torch intra-op threads of each rank
  double samples_per_s = 0.0;   ///< training samples per second of epoch wall time, all ranks
  int resumed_after = 0;        ///< epoch of the checkpoint this run continued from (0: none)
  /// Per movement, the median over its validation demonstrations of the DTW to the nearest
  /// other one (what a rollout is compared with), m; empty without rollout selection.
  std::vector<double> val_nn_dtw_m;
  /// A run latent's codes of the kept weights, per movement (model.bin's "run_codes"); empty
  /// without a run latent (a recipe's "run-latent").
  std::vector<ModelRunCodes> run_codes;
};

/// Trains a policy on `data`: executes the training split's demonstrations on the simulated arm
/// `sim` (clean and noisy rollouts, expert labels: ExecutionOptions; validation: the clean
/// rollouts of the validation split) - in autonomous mode each from its own start
/// (fromOwnStarts) - then fits the whole sequences. Sets torch to
/// one thread and deterministic algorithms, seeds torch's generator with options.seed before
/// initialisation, shuffles batches with a local generator. Prints one line per epoch to
/// `progress` (if not null, flushed). With options.dist.world_size > 1 this is one rank of a
/// data-parallel group (docs/training.md): it joins the group, takes shardRange() of every
/// global batch, of the validation samples and of the executed and scored rollouts, and sums
/// gradients and losses with Gloo all-reduce; every rank returns the same result. Throws
/// UserError for options that do not fit the data, a checkpoint of other data or options, and
/// a failed rendezvous or collective.
TrainResult trainPolicy(const PolicyData& data, const SimModel& sim, const TrainOptions& options, std::ostream* progress);

/// The law gain training uses for `o` on `sim` (model.bin's law.gain): in reference mode the
/// first-order inversion of the simulated servo over one tick, 1 / (1 − exp(−K T)), the net
/// learning the rest of the action; autonomous mode has no law (0).
double lawGain(const TrainOptions& o, const SimModel& sim);

/// The metadata JSON stored in model.bin: config, seed, data fingerprint, split, the autonomous
/// starts of the validation demonstrations ("starts"), epochs run, best epoch, final losses,
/// baselines; the world size and batch cap only when not 1 / not off. No wall time or date:
/// equal runs give equal text.
std::string modelMetadata(const PolicyData& data, const TrainOptions& options, const TrainResult& result);

/// Header of the model.bin for `result` (joints: nao::trainedJoints of the URDF in use).
ModelHeader modelHeader(const PolicyData& data, const TrainOptions& options, const TrainResult& result,
                        const std::vector<TrainedJoint>& joints);

/// Markdown model card: configuration, head, seed, data fingerprint, epochs, world size, wall
/// time and throughput, per-epoch losses and rollout scores, the one-step MSE beside the
/// baselines, the command line.
std::string modelCard(const PolicyData& data, const TrainOptions& options, const TrainResult& result,
                      const std::string& command_line, const std::string& model_path);

}  // namespace nao::tools
