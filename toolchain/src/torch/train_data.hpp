// The training's tensors (docs/policy.md "Head"): executed sequences as normalised inputs and
// chunk targets; the loss of a batch; sharing the simulated rollouts between ranks. Offline only
// (libtorch).
#pragma once

#include "data_parallel.hpp"
#include "policy_torch.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace nao::tools {

/// Executed sequences as the net trains on them, one entry per sequence.
struct SequenceTensors {
  std::vector<torch::Tensor> qn, an, rn;  ///< each [T_i, J], normalised inputs
  /// Each [T_i, J, C]: the chunk a(t) .. a(t+C−1) of the labels less the model's law (reference
  /// mode: gain·r), normalised; past the sequence's end the arm holds (a = 0, r = 0).
  std::vector<torch::Tensor> target;
  std::vector<torch::Tensor> action;  ///< each [T_i, J]: the label a(t) itself, rad (for MSE in rad²)
  std::vector<torch::Tensor> r;       ///< each [T_i, J]: r(t), rad (the law's input)
  std::vector<std::int64_t> movement;
  std::int64_t ticks = 0;  ///< all sequences together
  std::size_t size() const { return qn.size(); }
};

/// `seqs` normalised with the net's norm.* buffers, with targets for its head (chunk C, law.gain).
SequenceTensors toTensors(const PolicyNet& net, const std::vector<PolicySequence>& seqs);

/// Sequences `index` padded to the longest: the batch, targets [B,T,J,C], the labels in rad
/// [B,T,J], r [B,T,J] and the mask of real ticks [B,T].
struct Padded {
  PolicyBatch in;
  torch::Tensor target, action, r, mask;
  std::int64_t ticks = 0;  ///< real ticks
};
Padded pad(const SequenceTensors& t, const std::vector<std::size_t>& index);

/// Per real tick of `p`, summed: the training loss (the mean squared error over the chunk's J·C
/// normalised entries), and the squared error in rad² summed over J of the executed action's
/// first term (the chunk's a(t), plus the law) - comparable with the one-step baselines.
struct LossSums {
  torch::Tensor loss;  ///< scalar, differentiable
  double action_sse_rad2 = 0.0;
};
LossSums lossSums(const PolicyNet& net, const Padded& p);

/// Loss per tick and the executed action's MSE (rad², per joint) of `net` on `t`, one sequence at a
/// time; with a group each rank evaluates its shard and the sums are all-reduced.
struct SplitLoss {
  double loss = 0.0;      ///< the training loss per tick
  double mse_rad2 = 0.0;  ///< the first action's squared error per tick and joint
};
SplitLoss evaluateLoss(const PolicyNet& net, const SequenceTensors& t, ProcessGroup* group = nullptr);

/// Executed sequences kept in a file, so that training runs on the same data, execution options
/// and split share them (TrainOptions::execution_cache): exact doubles, little-endian. readSequences
/// returns false when the file does not exist; both throw UserError on a broken or unwritable file.
void writeSequences(const std::string& path, const std::vector<PolicySequence>& seqs);
bool readSequences(const std::string& path, std::vector<PolicySequence>& seqs);

/// Every rank's `mine`, in rank order, on every rank of `group`: each rank broadcasts its own
/// sequences (Gloo), so every rank holds the doubles their owner computed. A collective.
std::vector<PolicySequence> gatherSequences(ProcessGroup& group, std::vector<PolicySequence> mine);

/// make(demos) for the listed demonstrations, in list order. With a group each rank makes a
/// contiguous share and the shares are gathered (the sequences of one demonstration depend on it
/// alone), so every rank gets what one process would make.
template <class Make>
std::vector<PolicySequence> sharedSequences(ProcessGroup* g, const std::vector<int>& demos, Make&& make) {
  if (g == nullptr) return make(demos);
  const auto [b, e] = shardRange(static_cast<std::int64_t>(demos.size()), g->worldSize(), g->rank());
  const std::vector<int> mine(demos.begin() + b, demos.begin() + e);
  return gatherSequences(*g, mine.empty() ? std::vector<PolicySequence>{} : make(mine));
}

}  // namespace nao::tools
