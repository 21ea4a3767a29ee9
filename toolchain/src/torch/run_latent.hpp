// A per-run latent for training (the encoder of a conditional VAE, as in ACT).
#pragma once

#include "nao/model_file.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "train_data.hpp"

#include <torch/torch.h>

#include <cstdint>
#include <vector>

namespace nao::tools {

/// From the whole executed run (its normalised q sampled every `stride` ticks from tick 0, held
/// at its last tick past the end) the encoder infers z ~ N(μ, σ²) over K dimensions; z, projected
/// to d without a bias, is added to every encoder token. The net can then learn which of the
/// demonstrated variants (phase, period, centre of a cycle) a run follows instead of averaging
/// them. At run time a run takes the code P μ of a training demonstration (model.bin's
/// "run_codes": the medoid of the demonstrations whose starts are nearest its own, runCodeIndex);
/// a model without run codes runs with z = 0, the prior's mean.
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

/// The run codes of the training demonstrations and where their clean rollouts are among the
/// training tensors.
struct RunCodeSource {
  std::vector<ModelRunCodes> codes;               ///< per movement; names, q and dtw_m fixed, code by updateRunCodes
  std::vector<std::vector<std::size_t>> sequence;  ///< [movement][i]: the clean rollout of codes[movement].names[i]
};

/// Names, starts (PolicyDemo::start) and hand-path DTW table of the demonstrations whose clean
/// rollouts are in `train` (rollout 0), per movement of `data`, codes zero (d_model floats each).
RunCodeSource runCodeSource(const PolicyData& data, const std::vector<PolicySequence>& train, const ArmModel& arm,
                            int d_model);

/// Each code of `source` as `latent`'s P μ of its clean rollout in `t` (no draw: ε = 0).
void updateRunCodes(RunCodeSource& source, const SequenceTensors& t, RunLatentImpl& latent);

}  // namespace nao::tools
