// Checkpoints of a training run (docs/training.md): torch archives holding the trainable
// parameters in manifest order, Adam's state, the best weights so far, the history, and a key of
// everything that makes the run what it is except the world size, the epoch cap and the
// patience (those may change on resume). Offline only (libtorch).
#pragma once

#include "policy_train.hpp"

#include <ostream>
#include <string>
#include <vector>

namespace nao::tools {

/// The key a checkpoint must match to be resumed by a run of `o` on data `fingerprint`. With a
/// closed-loop phase, where it starts and its options (not its epoch count) are part of the key;
/// a checkpoint of the teacher-forced epochs alone (the key without them, `teacher_forced_only`)
/// may be resumed into it.
std::string checkpointKey(const TrainOptions& o, std::uint64_t fingerprint, bool teacher_forced_only = false);

/// The execution options' part of the checkpoint and execution-cache keys, written to `k`
/// (whose precision the caller sets). Options at their defaults add nothing, so older keys stay.
void writeExecutionKey(std::ostream& k, const ExecutionOptions& e);

struct Checkpoint {
  std::vector<torch::Tensor> best;
  int best_epoch = 0;
  std::vector<EpochStats> history;
  std::vector<torch::Tensor> ema;  ///< the moving average of the weights, empty without one
  std::int64_t ema_steps = 0;
  std::string key;  ///< the key it was written with
};

/// Writes the state aside and renames it over `path` (a run killed while saving leaves the
/// previous checkpoint whole). `ema` (empty: none) is the moving average of the weights after
/// `ema_steps` updates. Throws UserError when it cannot.
void writeCheckpoint(const std::string& path, const std::string& key, const std::vector<torch::Tensor>& params,
                     torch::optim::Adam& optimiser, const std::vector<torch::Tensor>& best, int best_epoch,
                     const std::vector<EpochStats>& history, const std::vector<torch::Tensor>& ema = {},
                     std::int64_t ema_steps = 0);

/// Reads `path` into `params` and `optimiser`; returns the best weights and the history. The
/// checkpoint's key must be one of `keys` (Checkpoint::key says which). Throws UserError for
/// another run's checkpoint, an unreadable file or one without a finished epoch.
Checkpoint readCheckpoint(const std::string& path, const std::vector<std::string>& keys,
                          std::vector<torch::Tensor>& params, torch::optim::Adam& optimiser);

}  // namespace nao::tools
