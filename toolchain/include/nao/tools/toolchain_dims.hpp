// The policy dimensions the toolchain runs in process: the trainer's selection rollouts and the
// evaluator's replay drive the runtime's own step, a template over the dimensions, so only the
// dimensions instantiated here run there. A model of others runs in the nao_rt built for it
// (toolchain/nao build --model FILE). Each entry is one more instantiation of the step in the
// trainer, the evaluator and test_model_quality (build time): docs/autonomous.md's 24-tick window
// was trained and evaluated with PolicyDims<32, 4, 2, 2, 64, 64, 64, 24> added. Offline code.
#pragma once

#include "nao/policy_config.hpp"
#include "nao/policy_weights.hpp"
#include "nao/input_error.hpp"

#include <string>
#include <utility>

namespace nao::tools {

/// True if `a` and `b` compute the same step (everything the dimensions fix; the chunk, the
/// movements and the clock are bound at run time).
inline bool sameComputation(const PolicyArch& a, const PolicyArch& b) {
  return a.d_model == b.d_model && a.heads == b.heads && a.encoder_layers == b.encoder_layers &&
         a.decoder_layers == b.decoder_layers && a.ffn_hidden == b.ffn_hidden && a.tokens == b.tokens &&
         a.features == b.features && a.window == b.window;
}

/// True if `arch`'s step is one of the toolchain's dimensions.
inline bool hasToolchainDims(const PolicyArch& arch) {
  return sameComputation(arch, PaperPolicyDims::arch()) || sameComputation(arch, SmallPolicyDims::arch());
}

/// A dimensions type passed as a value: DimsTag<D>::type is D.
template <class D>
struct DimsTag {
  using type = D;
};

/// f(DimsTag<Dims>{}) for the toolchain's dimensions that compute `arch`'s step;
/// InputError naming `what` when none does.
template <class F>
decltype(auto) withToolchainDims(const PolicyArch& arch, const char* what, F&& f) {
  if (sameComputation(arch, PaperPolicyDims::arch())) return std::forward<F>(f)(DimsTag<PaperPolicyDims>{});
  if (sameComputation(arch, SmallPolicyDims::arch())) return std::forward<F>(f)(DimsTag<SmallPolicyDims>{});
  throw InputError(std::string(what) +
                  " needs the runtime's step in process, compiled here for the paper and small dimensions "
                  "(toolchain_dims.hpp); a model of other dimensions (d_model, heads, layers, FFN, "
                  "window) runs in the nao_rt built for it (toolchain/nao build --model FILE)");
}

}  // namespace nao::tools
