// The attention ablation's probe (docs/analysis.md): the action a tick would have executed with
// some body parts left out of the decoder's cross-attention. Evaluation code (the in-process
// replay, toolchain/src/eval/replica.hpp), not part of a run: it builds on the runtime's step
// pieces (decodePolicyTick's mask, ensembledAction) and adds nothing to nao_core.
#pragma once

#include "nao/policy.hpp"

#include <Eigen/Core>

namespace nao::tools {

/// After stepPolicy(w, ws, in) for a tick, the action that tick would have executed with the
/// body parts in `masked` (bit j: part j) left out of every decoder layer's cross-attention over
/// the whole window. The tick is decoded again with the mask, its action taken as
/// commitPolicyTick would take it, and the tick decoded once more without the mask, so ws is left
/// as stepPolicy left it (the chunk ring untouched). No allocation; it costs two decoder passes.
template <class Dims>
Eigen::Matrix<float, 5, 1> ablatedAction(const PolicyWeights<Dims>& w, PolicyWorkspace<Dims>& ws, const PolicyInput& in,
                                         unsigned masked) {
  --ws.ticks;  // back to the tick stepPolicy just made (its encoder state is still in the rings)
  decodePolicyTick(w, ws, masked);
  Eigen::Matrix<float, 5, 1> a = ensembledAction(w, ws);
  if (w.conditioning == Conditioning::kReference) a += (w.law_gain.array() * in.r.array()).matrix();
  decodePolicyTick(w, ws, 0);
  ++ws.ticks;
  return a;
}

}  // namespace nao::tools
