// A policy's weights as one named vector per manifest tensor, seeded random values shaped like
// an initialisation (TestModel, randomModel), for the suites of the streaming step and its
// binding (test_policy.cpp, test_policy_binding.cpp).
#pragma once

#include "nao/policy.hpp"
#include "support/random_policy.hpp"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace nao::test {

/// Every manifest tensor as its own std::vector<float>, found by name.
struct TestModel {
  std::vector<TensorSpec> manifest;
  std::vector<std::vector<float>> data;
  std::map<std::string, std::size_t> index;

  std::vector<float>& operator[](const std::string& name) { return data.at(index.at(name)); }
  const std::vector<float>& operator[](const std::string& name) const { return data.at(index.at(name)); }
  const TensorSpec& spec(const std::string& name) const { return manifest.at(index.at(name)); }
  std::vector<const float*> pointers() const {
    std::vector<const float*> p;
    for (const std::vector<float>& t : data) p.push_back(t.data());
    return p;
  }
};

/// Random weights shaped like a real initialisation (Xavier-uniform matrices), with non-zero
/// biases, layer-norm parameters and embeddings large enough that every term shows in the output.
/// law.gain is about 1; head.ensemble_decay is `decay`.
inline TestModel randomModel(const PolicyArch& arch, std::uint64_t seed, bool zero_step_embedding, double decay = 0.3) {
  const auto startsWith = [](const std::string& s, const char* p) { return s.rfind(p, 0) == 0; };
  const auto endsWith = [](const std::string& s, const std::string& e) {
    return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
  };
  const auto uniform = [](std::mt19937_64& rng, double lo, double hi) { return uniformFloat(rng, lo, hi); };
  TestModel m;
  m.manifest = policyManifest(arch);
  std::mt19937_64 rng(seed);
  for (std::size_t i = 0; i < m.manifest.size(); ++i) {
    const TensorSpec& s = m.manifest[i];
    m.index[s.name] = i;
    std::vector<float> v(s.count());
    const std::string& n = s.name;
    for (float& x : v) {
      if (startsWith(n, "norm.") && endsWith(n, "_std"))
        x = uniform(rng, 0.05, 0.5);
      else if (startsWith(n, "norm."))
        x = uniform(rng, -0.3, 0.3);
      else if (n == "centroids")
        x = uniform(rng, -1.5, 1.5);
      else if (startsWith(n, "embed.joint") || n == "embed.movement" || n == "embed.step")
        x = uniform(rng, -0.5, 0.5);
      else if (endsWith(n, ".age_bias"))
        x = uniform(rng, -1.0, 1.0);  // a clear preference of ages, different per head
      else if (n == "head.ensemble_decay")
        x = static_cast<float>(decay);
      else if (endsWith(n, ".gain"))
        x = uniform(rng, 0.8, 1.2);
      else if (s.shape.size() == 2) {
        const double a = std::sqrt(6.0 / (s.shape[0] + s.shape[1]));
        x = uniform(rng, -a, a);
      } else {
        x = uniform(rng, -0.1, 0.1);  // biases, layer-norm biases
      }
    }
    if (n == "embed.step" && zero_step_embedding) std::fill(v.begin(), v.end(), 0.0f);
    m.data.push_back(std::move(v));
  }
  return m;
}

inline PolicyInput randomInput(std::mt19937_64& rng, int movement, int step) {
  return randomPolicyInput(rng, movement, step, 1.5);
}

inline bool bitwiseEqual(const Eigen::Matrix<float, 5, 1>& a, const Eigen::Matrix<float, 5, 1>& b) {
  return std::memcmp(a.data(), b.data(), sizeof(float) * 5) == 0;
}

/// The architecture of Dims with these table and head sizes.
template <class Dims>
PolicyArch archOf(int chunk = 1, int movements = 3, int clusters = 10, int max_steps = 256) {
  PolicyArch a = Dims::arch();
  a.chunk = chunk;
  a.movements = movements;
  a.clusters = clusters;
  a.max_steps = max_steps;
  return a;
}

/// A random model bound for Dims, with its workspace.
template <class Dims>
struct Fixture {
  TestModel model;
  std::vector<const float*> ptrs;
  PolicyWeights<Dims> w;
  std::unique_ptr<PolicyWorkspace<Dims>> ws = makePolicyWorkspace<Dims>();

  Fixture(std::uint64_t seed, Conditioning c, bool zero_step, const PolicyArch& arch = Dims::arch())
      : model(randomModel(arch, seed, zero_step)),
        ptrs(model.pointers()),
        w(bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c)) {}

  /// A one-tick rollout (fresh stream).
  Eigen::Matrix<float, 5, 1> run(const PolicyInput& in) {
    resetPolicyStream(*ws);
    return stepPolicy(w, *ws, in);
  }
  /// The actions of a whole rollout, from a fresh stream.
  std::vector<Eigen::Matrix<float, 5, 1>> rollout(const std::vector<PolicyInput>& seq) {
    resetPolicyStream(*ws);
    std::vector<Eigen::Matrix<float, 5, 1>> out;
    for (const PolicyInput& in : seq) out.push_back(stepPolicy(w, *ws, in));
    return out;
  }
};

}  // namespace nao::test
