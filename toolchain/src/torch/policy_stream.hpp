// The policy streamed one tick at a time in libtorch, as the runtime's stepPolicy runs it
// (nao/policy.hpp): the new tick's J encoder tokens through every layer against a cache of the
// last W ticks' keys and values, the decoder's J action tokens against the cached memory, the
// head's chunk and the temporal ensemble of the last C chunks. Differentiable, for the trainer's
// closed-loop rollouts (docs/autonomous.md): each tick costs its own tokens, where the sequence
// forward (PolicyNetImpl::forward) would recompute the whole window. Offline only (libtorch).
//
// Shapes: B runs, J tokens (joints), d = d_model, H heads, d_h = d / H, n ≤ W ticks in the window.
#pragma once

#include "policy_torch.hpp"

#include <torch/torch.h>

#include <vector>

namespace nao::tools {

/// What a stream carries from tick to tick (the runtime's key/value rings and chunk ring).
struct PolicyStream {
  std::vector<torch::Tensor> enc_k, enc_v;      ///< per encoder layer [B,H,n·J,d_h], oldest tick first
  std::vector<torch::Tensor> cross_k, cross_v;  ///< per decoder layer, the memory's cross keys/values, the same
  torch::Tensor pending;  ///< [B,J,C] rad: entry k, the ensemble's weighted sum of every chunk's entry for tick t + k
  std::int64_t ticks = 0;                       ///< ticks streamed since the start
};

/// One tick's inputs for B runs.
struct StreamInput {
  torch::Tensor q;         ///< [B,J] float, measured angles, rad
  torch::Tensor a_prev;    ///< [B,J] float, the applied action of the last tick, rad (0 at the start)
  torch::Tensor movement;  ///< [B] int64
  torch::Tensor step;      ///< [B] int64: the step row (the runtime's min(tick, S − 1))
  torch::Tensor z;         ///< [B,d] float: the run code added to every encoder token (undefined: 0)
};

/// One tick of an autonomous-mode net (chunk C ≥ 1) for the B runs of `s` (a fresh PolicyStream
/// starts them): the network's action a(t) [B,J] in rad, the chunks de-normalised and ensembled
/// over the last min(t + 1, C) ticks with head.ensemble_decay (the runtime's net_action;
/// autonomous mode adds no law). Throws std::invalid_argument for a reference-mode net.
torch::Tensor streamStep(const PolicyNetImpl& net, PolicyStream& s, const StreamInput& in);

}  // namespace nao::tools
