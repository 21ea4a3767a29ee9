#include "run_latent.hpp"

#include "nao/tools/evaluate.hpp"
#include "nao/metrics.hpp"

#include <stdexcept>
#include <string>

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

RunCodeSource runCodeSource(const PolicyData& data, const std::vector<PolicySequence>& train, const ArmModel& arm,
                            int d_model) {
  RunCodeSource s;
  s.codes.resize(static_cast<std::size_t>(data.movements()));
  s.sequence.resize(s.codes.size());
  std::vector<std::vector<HandPath>> paths(s.codes.size());
  for (std::size_t i = 0; i < train.size(); ++i) {
    if (train[i].rollout != 0) continue;
    const PolicyDemo& demo = data.demos.at(static_cast<std::size_t>(train[i].demo));
    const auto m = static_cast<std::size_t>(demo.movement);
    s.codes[m].names.push_back(demo.name);
    s.codes[m].q.push_back(demo.start);
    s.sequence[m].push_back(i);
    paths[m].push_back(handPath(arm, demo.f));
  }
  for (std::size_t m = 0; m < s.codes.size(); ++m) {
    ModelRunCodes& c = s.codes[m];
    const std::size_t n = c.size();
    c.d = d_model;
    c.code.assign(n * static_cast<std::size_t>(d_model), 0.0f);
    c.dtw_m.assign(n * n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t k = i + 1; k < n; ++k) c.dtw_m[i * n + k] = c.dtw_m[k * n + i] = rt::dtwMeanDistance(paths[m][i], paths[m][k]);
  }
  return s;
}

void updateRunCodes(RunCodeSource& source, const SequenceTensors& t, RunLatentImpl& latent) {
  torch::NoGradGuard no_grad;
  for (std::size_t m = 0; m < source.codes.size(); ++m) {
    if (source.sequence[m].empty()) continue;
    const Padded p = pad(t, source.sequence[m]);
    const torch::Tensor z = latent.forward(p, torch::zeros({p.in.qn.size(0), latent.dims})).z_embedded.contiguous();
    std::vector<float>& code = source.codes[m].code;
    if (static_cast<std::size_t>(z.numel()) != code.size()) throw std::logic_error("run codes: width mismatch");
    std::copy(z.data_ptr<float>(), z.data_ptr<float>() + z.numel(), code.begin());
  }
}

}  // namespace nao::tools
