// A libtorch policy net with seeded weights moved away from its initialisation, for the suites
// that compare the torch module with the runtime's step (test_torch_*.cpp).
#pragma once

#include "nao/arm_model.hpp"
#include "nao/policy_config.hpp"
#include "policy_torch.hpp"

#include <torch/torch.h>

#include <cstdint>
#include <vector>

namespace nao::test {

// A fresh net of `arch` moved away from its initialisation (LN gains 1, biases 0, zero step rows)
// so every term counts: normalisation statistics, key poses, a law of 1.0894 (reference mode),
// an ensemble decay of 0.3 (chunks).
inline tools::PolicyNet perturbedNet(const PolicyArch& arch, Conditioning c,
                                     const std::vector<std::vector<JointVector>>& centroids, std::uint64_t seed) {
  torch::manual_seed(seed);
  tools::PolicyNet net(arch, c);
  torch::NoGradGuard no_grad;
  for (torch::Tensor& p : net->trainableParameters()) p.add_(torch::randn_like(p) * 0.05);
  tools::NormStats stats;
  for (int j = 0; j < kNumJoints; ++j) {
    stats.q_mean[j] = 0.1 * j;
    stats.q_std[j] = 0.5 + 0.1 * j;
    stats.a_mean[j] = 0.001 * j;
    stats.a_std[j] = 0.02 + 0.01 * j;
    stats.r_mean[j] = -0.1 * j;
    stats.r_std[j] = 0.7;
  }
  net->setNormalisation(stats);
  net->setCentroids(centroids);
  net->setLawGain(1.0894);
  net->setEnsembleDecay(0.3);
  net->eval();
  return net;
}

}  // namespace nao::test
