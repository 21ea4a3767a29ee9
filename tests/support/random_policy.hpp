// A policy with seeded random weights shaped like a fresh initialisation, for tests of code
// around the policy (controller, ring buffer): actions of a few mrad, key poses inside the arm's
// limits. Not a trained model: closed-loop imitation quality is tested with trained ones.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/policy.hpp"

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace nao::test {

/// Uniform in [lo, hi) from the generator's raw bits (std distributions differ between
/// standard libraries).
inline float uniformFloat(std::mt19937_64& rng, double lo, double hi) {
  return static_cast<float>(lo + (hi - lo) * (static_cast<double>(rng() >> 11) * 0x1.0p-53));
}

/// A policy input with q and r uniform in ±q_range rad and a(t−1) in ±0.1 rad.
inline PolicyInput randomPolicyInput(std::mt19937_64& rng, int movement, int step, double q_range) {
  PolicyInput in;
  for (int j = 0; j < kNumJoints; ++j) {
    in.q[j] = uniformFloat(rng, -q_range, q_range);
    in.a_prev[j] = uniformFloat(rng, -0.1, 0.1);
    in.r[j] = uniformFloat(rng, -q_range, q_range);
  }
  in.movement = movement;
  in.step = step;
  return in;
}

/// One float vector per manifest entry of `arch`, seeded pseudo-random values in [-1, 1): a
/// well-formed tensor set for file-format and codegen tests (not a usable policy).
inline std::vector<std::vector<float>> randomManifestTensors(const PolicyArch& arch, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<std::vector<float>> out;
  for (const TensorSpec& t : policyManifest(arch)) {
    std::vector<float> v(t.count());
    for (float& x : v) x = u(rng);
    out.push_back(std::move(v));
  }
  return out;
}

struct RandomPolicy {
  std::vector<std::vector<float>> tensors;  ///< manifest order
  std::vector<const float*> pointers;
};

inline RandomPolicy makeRandomPolicy(const PolicyArch& arch, const ArmModel& arm, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  auto uniform = [&rng](double lo, double hi) { return uniformFloat(rng, lo, hi); };
  RandomPolicy p;
  for (const TensorSpec& t : policyManifest(arch)) {
    std::vector<float> v(t.count());
    const std::string& n = t.name;
    auto ends = [&n](const char* s) {
      const std::string e(s);
      return n.size() >= e.size() && n.compare(n.size() - e.size(), e.size(), e) == 0;
    };
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (n == "centroids") {
        const int j = static_cast<int>(i % kNumJoints);
        v[i] = uniform(arm.q_min[j], arm.q_max[j]);
      } else if (ends("_std")) {
        v[i] = n == "norm.a_std" ? 0.01f : 0.5f;
      } else if (ends("_mean") || n == "embed.step" || n == "law.gain") {
        v[i] = 0.0f;  // law.gain 0: the network alone acts, as a fresh reference-mode net over no law
      } else if (n == "head.ensemble_decay") {
        v[i] = 0.5f;
      } else if (ends(".gain")) {
        v[i] = 1.0f;
      } else if (t.shape.size() == 2) {
        const double a = std::sqrt(6.0 / (t.shape[0] + t.shape[1]));
        v[i] = uniform(-a, a);
      } else {
        v[i] = uniform(-0.1, 0.1);
      }
    }
    p.tensors.push_back(std::move(v));
  }
  for (const auto& t : p.tensors) p.pointers.push_back(t.data());
  return p;
}

}  // namespace nao::test
