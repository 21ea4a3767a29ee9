// What a model.bin's metadata JSON tells a run beyond the tensors (DESIGN §8, "model.bin is
// self-sufficient"): the retargeting setting its data was made with, the residual gain of a
// reference model, the linear AR base and phase grid of an autonomous one. The autonomous starts
// are model_file.hpp's (modelStarts). Configure-time code: parses JSON, allocates, throws.
#pragma once

#include "nao/policy.hpp"
#include "nao/retarget.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nao {

/// `defaults` with the retargeting setting a model's metadata records (data.retarget: priority,
/// lambda_q, posture_weights) applied; unchanged when the metadata has none. Throws
/// std::runtime_error naming `origin` for a setting that is present but unusable.
RetargetParams modelRetargetSetting(const std::string& metadata_json, const RetargetParams& defaults,
                                    const std::string& origin);

/// The residual gain a reference-mode model was trained with (metadata training.residual_gain,
/// PolicyWeights::residual_gain); 0 when the metadata has none. Throws std::runtime_error naming
/// `origin` for a value that is present but not a finite number in [0, 100].
float modelResidualGain(const std::string& metadata_json, const std::string& origin);

/// The phase grid an autonomous model's step embedding was trained on (metadata
/// training.phase_ticks, ControllerParams::phase_ticks); 0 when the metadata has none. Throws
/// std::runtime_error naming `origin` for a value that is present but not an integer in [1, 1e5].
std::int64_t modelPhaseTicks(const std::string& metadata_json, const std::string& origin);

/// The linear AR base an autonomous model was trained over (metadata training.linear_ar: per
/// movement, per joint {"order", "c", "beta", "alpha"}; PolicyWeights::linear_ar), as doubles.
struct LinearArCoefficients {
  std::vector<std::array<double, 5>> c, beta;                               ///< [movement][joint]
  std::vector<std::array<std::array<double, 5>, kPolicyArMaxOrder>> alpha;  ///< [movement][k − 1][joint]
  bool empty() const { return c.empty(); }
};

/// Empty when the metadata has none. Throws std::runtime_error naming `origin` for one that is
/// present but unusable (not `movements` movements of 5 joints, an order outside 1..12, a
/// coefficient that is not a finite number).
LinearArCoefficients modelLinearAr(const std::string& metadata_json, int movements, const std::string& origin);

/// `k` as the runtime's float base (on = !k.empty() and one entry per movement).
template <int M>
LinearArBase<M> linearArBase(const LinearArCoefficients& k) {
  LinearArBase<M> b;
  b.on = !k.empty() && k.c.size() == static_cast<std::size_t>(M);
  if (!b.on) return b;
  for (std::size_t m = 0; m < static_cast<std::size_t>(M); ++m)
    for (std::size_t j = 0; j < 5; ++j) {
      b.c[m][j] = static_cast<float>(k.c[m][j]);
      b.beta[m][j] = static_cast<float>(k.beta[m][j]);
      for (std::size_t i = 0; i < static_cast<std::size_t>(kPolicyArMaxOrder); ++i)
        b.alpha[m][i][j] = static_cast<float>(k.alpha[m][i][j]);
    }
  return b;
}

}  // namespace nao
