// A per-run latent for training (the encoder of a conditional VAE, as in ACT).
#pragma once

#include "train_data.hpp"

#include <torch/torch.h>

#include <cstdint>

namespace nao::tools {

/// From the whole executed run (its normalised q sampled every `stride` ticks from tick 0, held
/// at its last tick past the end) the encoder infers z ~ N(μ, σ²) over K dimensions; z, projected
/// to d without a bias, is added to every encoder token. The net can then learn which of the
/// demonstrated variants (phase, period, centre of a cycle) a run follows instead of averaging
/// them. At run time z = 0, the prior's mean, so the projection adds nothing: model.bin and
/// nao_rt are unchanged, and the KL term trains the net to make one coherent variant there.
struct RunLatentImpl : torch::nn::Module {
  static constexpr std::int64_t kSamples = 48, kStride = 4, kHidden = 128;
  RunLatentImpl(std::int64_t latent_dims, std::int64_t d_model);
  struct Draw {
    torch::Tensor z_embedded;  ///< [B, d] to add to every encoder token of run b
    torch::Tensor kl;          ///< [B] KL(N(μ, σ²) ‖ N(0, I)) of each run, nats
  };
  /// `p`'s runs (qn, and mask for their lengths), with the standard normal draws `eps` [B, K].
  Draw forward(const Padded& p, const torch::Tensor& eps);
  torch::nn::Linear hidden{nullptr}, moments{nullptr}, project{nullptr};
  std::int64_t dims;
};
TORCH_MODULE(RunLatent);

}  // namespace nao::tools
