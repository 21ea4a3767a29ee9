// Training the policy (docs/policy.md): seeded, one thread per rank, deterministic for a fixed
// world size; data-parallel over a Gloo process group (docs/training.md); early stopping on the
// validation loss keeps the best weights; checkpoints and resume; export to model.bin and a
// model card. Offline only (libtorch).
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy_config.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "data_parallel.hpp"
#include "policy_torch.hpp"

#include <cstdint>
#include <iosfwd>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace nao {
struct LinearArCoefficients;  // nao/model_metadata.hpp
}

namespace nao::tools {

struct TrainOptions {
  std::string config_name = "paper";  ///< recorded in the metadata ("paper" | "small" | ...)
  PolicyArch arch = paperArch();      ///< movements and clusters must match the data
  Conditioning conditioning = Conditioning::kReference;
  std::uint64_t seed = 1;             ///< weights, split and batch order
  int max_epochs = 200;               ///< iteration cap; early stopping usually ends sooner
  int patience = 10;                  ///< epochs without a new best validation loss before stopping
  double val_fraction = 0.2;          ///< of each movement's demonstrations
  int batch = 2;                      ///< sequences (whole executed rollouts) per optimiser step
  double lr = 6e-5;                   ///< Adam
  ExecutionOptions execution;         ///< how the demonstrations are executed and labelled
  DistOptions dist;                   ///< world size 1: this process alone, the single-process loop
  std::string checkpoint;             ///< if set, rank 0 writes the state here after every epoch
  std::string resume;                 ///< if set, continue from this checkpoint (any world size)
  int max_batches = 0;                ///< > 0: each epoch stops after this many global batches (timing)
  bool live_progress = false;         ///< rank 0 also redraws a '\r' line during the epoch (terminals)
  /// Reference mode: the net learns the residual of a = g·r (r = f(t+1) − q). < 0: g inverts the
  /// simulated first-order servo over one tick, 1 / (1 − exp(−K T)); 0: no residual. Autonomous: 0.
  double residual_gain = -1.0;
  /// DAgger (docs/policy.md "Data"): after each of the epochs dagger_start .. dagger_start +
  /// dagger_rounds − 1 the current net is rolled out on the simulated arm from every training
  /// demonstration's start (executePolicyRollouts through the runtime's stepPolicy; β-mixing and
  /// a drift bound in `execution`), the states it reaches are labelled by the expert, and the
  /// sequences join the training set for the remaining epochs (normalisation statistics and
  /// validation set unchanged). 0: off. Only the paper and small architectures (the runtime's
  /// compiled Dims), no resume; any world size (each rank rolls out its share).
  int dagger_rounds = 0;
  int dagger_start = 2;  ///< 1-based epoch after which the first round runs
  /// Model selection on rollouts (autonomous mode, paper §4.1; docs/policy.md): after every epoch
  /// the net is rolled out on the simulated arm from each validation demonstration's start (as
  /// nao_rt's autonomous runs: its streaming inference, no human input), and the exported epoch is
  /// the one with the lowest rollout DTW (per movement the median over its validation
  /// demonstrations of the hand-path DTW to the nearest validation demonstration; the mean over
  /// movements), not the lowest one-step validation loss. Patience counts on it too. Only the
  /// paper and small architectures (the runtime's compiled Dims).
  bool select_by_rollout = false;
  /// Autonomous mode: the net learns the residual over the linear AR baseline (linear_ar.hpp),
  /// fitted per movement on the training split's feature trajectories (order per joint chosen on
  /// the validation split's, up to 12), as nao_toolchain evaluate fits it; the head starts at
  /// zero, so the untrained net is that baseline (with select_by_rollout, scored as "epoch 0").
  bool ar_residual = false;
  /// Autonomous mode (docs/policy.md): > 0 indexes the step embedding by the movement's phase,
  /// floor(t·phase_ticks / L) for tick t of a demonstration of L samples (nao_rt: a run of L
  /// ticks), instead of by t. Not with a DAgger drift bound (a cut rollout's L is not its
  /// demonstration's).
  int phase_ticks = 0;
  /// Autonomous mode (docs/policy.md "Canonical pace"): set, every demonstration of movement m
  /// is trained on at the pace of m's shortest training demonstration (pacedData onto
  /// paceTemplates of the training split, linearly or by DTW), then held, at its own length. The
  /// rollouts are still scored against the demonstrations as they are.
  std::optional<PaceMethod> canonical_pace;
};

/// One DAgger round of a training run.
struct DaggerRound {
  int after_epoch = 0;         ///< 1-based
  std::size_t sequences = 0;   ///< added to the training set
  std::size_t ticks = 0;
  std::size_t expert_ticks = 0;  ///< of those, executed by the expert (β-mixing)
  double drift_rad = 0.0;      ///< largest |q(t) − f(t)| the policy's rollouts reached
  double seconds = 0.0;        ///< wall time (card only, never model.bin)
};

/// The residual gain training uses for `o` on `sim` (see TrainOptions::residual_gain).
double residualGain(const TrainOptions& o, const SimModel& sim);

struct EpochStats {
  int epoch = 0;             ///< 1-based
  double train_loss = 0.0;   ///< mean normalised MSE over the epoch's batches (weighted by size)
  double val_loss = 0.0;     ///< normalised MSE on the validation split after the epoch
  double val_mse_rad2 = 0.0; ///< the same in rad^2
  double seconds = 0.0;      ///< wall time of the epoch (never written to model.bin)
  std::size_t samples = 0;   ///< training samples of the epoch, all ranks together
  /// TrainOptions::select_by_rollout: the selection score (m) and its per-movement medians
  /// (the latter not kept by checkpoints); NaN / empty when off.
  double rollout_dtw_m = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> rollout_dtw_per_movement_m;
};

/// Loss of a model on a split, normalised (what is optimised) and in rad^2.
struct SplitLoss {
  double normalised = 0.0;
  double mse_rad2 = 0.0;
};

struct TrainResult {
  PolicyNet net{nullptr};       ///< best-validation weights, norm.* and centroids set
  PolicySplit split;
  NormStats stats;
  std::uint64_t fingerprint = 0;
  std::size_t train_samples = 0, val_samples = 0;  ///< ticks
  std::size_t train_sequences = 0;
  double expert_worst_miss_rad = 0.0;  ///< largest end-of-tick miss of the expert (clean rollouts)
  double execution_seconds = 0.0;      ///< wall time of executing the rollouts
  double residual_gain = 0.0;          ///< g of the exported model (metadata training.residual_gain)
  std::vector<EpochStats> history;
  int best_epoch = 0;           ///< 1-based epoch whose weights were kept
  SplitLoss train, val;         ///< of the kept weights
  Baselines train_baselines, val_baselines;  ///< rad^2
  double seconds = 0.0;         ///< total wall time
  int world_size = 1;           ///< ranks that trained it
  int threads_per_rank = 1;     ///< torch intra-op threads of each rank
  double samples_per_s = 0.0;   ///< training samples per second of epoch wall time, all ranks
  int resumed_after = 0;        ///< epoch of the checkpoint this run continued from (0: none)
  std::vector<DaggerRound> dagger;  ///< the DAgger rounds run, in order (TrainOptions::dagger_rounds)
  /// TrainOptions::select_by_rollout: per movement, the median over its validation
  /// demonstrations of the DTW to the nearest other one (what a rollout is compared with), m.
  std::vector<double> val_nn_dtw_m;
  /// TrainOptions::canonical_pace: per movement, the template demonstration (index into the
  /// data's demos; metadata training.canonical_pace); empty when off.
  std::vector<int> pace_templates;
  /// select_by_rollout: the net before the first epoch, scored the same way (epoch 0; with
  /// ar_residual that is the linear AR baseline itself): reported as the bar, never exported.
  /// Epoch −1: not scored (off, or resumed).
  EpochStats epoch0 = [] {
    EpochStats e;
    e.epoch = -1;
    return e;
  }();
};

/// Trains a policy on `data`: executes the training split's demonstrations on the simulated arm
/// `sim` (clean and noisy rollouts, expert labels: ExecutionOptions; validation: the clean
/// rollouts of the validation split), then fits the whole sequences. Sets torch to one thread and deterministic algorithms, seeds
/// torch's generator with options.seed before initialisation, shuffles batches with a local
/// generator. Prints one line per epoch to `progress` (if not null, flushed).
/// With options.dist.world_size > 1 this is one rank of a data-parallel group: it joins the
/// group, takes shardRange() of every global batch and of the validation samples, and sums
/// gradients and losses with Gloo all-reduce; every rank returns the same result. World size 1
/// never touches c10d and gives the bytes of the single-process trainer.
/// Throws UserError for options that do not fit the data (architecture movements/clusters
/// differ from the data's, no validation demonstration, bad batch/epochs/patience/lr), a
/// checkpoint of other data or options, and a failed rendezvous or collective (a rank died).
TrainResult trainPolicy(const PolicyData& data, const SimModel& sim, const TrainOptions& options, std::ostream* progress);

/// One DAgger round's sequences (TrainOptions::dagger_rounds): `net`'s present weights bound to
/// the runtime's streaming inference (nao/policy.hpp stepPolicy, the policy nao_rt runs; the
/// paper or small architecture) and rolled out from each listed demonstration's start by
/// executePolicyRollouts (rollout = −round; `labels` false: unlabelled, for scoring where the
/// policy goes; `align_pool`: executePolicyRollouts'). Throws UserError for another architecture.
std::vector<PolicySequence> daggerRollouts(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                                           const ExecutionOptions& execution, const PolicyNet& net, int round,
                                           bool labels = true, const std::vector<PolicySequence>& align_pool = {});

/// Every rank's `mine`, in rank order, on every rank of `group`: each rank broadcasts its own
/// sequences (Gloo), so every rank holds the doubles their owner computed. A collective: every
/// rank calls it. The training shares out its simulated rollouts this way (each rank executes
/// a contiguous share of the demonstrations; docs/training.md).
std::vector<PolicySequence> gatherSequences(ProcessGroup& group, std::vector<PolicySequence> mine);

/// Per-movement linear AR models as nao_rt reads them from the metadata (training.linear_ar,
/// doubles; linearArBase makes the runtime's float base of them).
LinearArCoefficients linearArCoefficients(const std::vector<LinearArModel>& models);

/// Normalised and rad^2 MSE of `net` on `sequences` (evaluation mode, no gradients).
SplitLoss evaluatePolicy(const PolicyNet& net, const std::vector<PolicySequence>& sequences);

/// The metadata JSON stored in model.bin: config, seed, data fingerprint, split, epochs run,
/// best epoch, final losses, baselines; the world size and batch cap only when not 1 / not
/// off (so single-process files keep their bytes). No wall time or date: equal runs give equal text.
std::string modelMetadata(const PolicyData& data, const TrainOptions& options, const TrainResult& result);

/// Header of the model.bin for `result` (joints: nao::trainedJoints of the URDF in use).
ModelHeader modelHeader(const PolicyData& data, const TrainOptions& options, const TrainResult& result,
                        const std::vector<TrainedJoint>& joints);

/// Markdown model card: configuration, layer-norm placement, seed, data fingerprint, epochs,
/// world size, threads per rank, wall time and throughput, per-epoch losses, validation MSE vs
/// the baselines, the command line.
std::string modelCard(const PolicyData& data, const TrainOptions& options, const TrainResult& result,
                      const std::string& command_line, const std::string& model_path);

}  // namespace nao::tools
