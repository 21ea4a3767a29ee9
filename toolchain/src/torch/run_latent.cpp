#include "run_latent.hpp"

namespace nao::tools {

RunLatentImpl::RunLatentImpl(std::int64_t latent_dims, std::int64_t d_model) : dims(latent_dims) {
  hidden = register_module("hidden", torch::nn::Linear(kSamples * kNumJoints, kHidden));
  moments = register_module("moments", torch::nn::Linear(kHidden, 2 * latent_dims));
  project = register_module("project", torch::nn::Linear(torch::nn::LinearOptions(latent_dims, d_model).bias(false)));
}

RunLatentImpl::Draw RunLatentImpl::forward(const Padded& p, const torch::Tensor& eps) {
  const std::int64_t n = p.in.qn.size(0);
  // Tick k·stride of each run, or its last tick once the run has ended.
  const torch::Tensor last = p.mask.sum(1).to(torch::kInt64) - 1;                              // [B]
  const torch::Tensor ticks = torch::arange(kSamples, torch::kInt64).mul(kStride).view({1, kSamples});
  const torch::Tensor at = torch::minimum(ticks.expand({n, kSamples}), last.view({n, 1}));      // [B,S]
  const torch::Tensor sampled = p.in.qn.gather(1, at.unsqueeze(-1).expand({n, kSamples, kNumJoints}));
  const torch::Tensor m = moments->forward(torch::relu(hidden->forward(sampled.reshape({n, -1}))));
  const torch::Tensor mu = m.slice(1, 0, dims), log_var = m.slice(1, dims, 2 * dims).clamp(-10.0, 10.0);
  Draw d;
  d.z_embedded = project->forward(mu + (0.5 * log_var).exp() * eps);
  d.kl = 0.5 * (mu.square() + log_var.exp() - 1.0 - log_var).sum(1);
  return d;
}

}  // namespace nao::tools
