// The synthesiser's random numbers: std::mt19937_64 with portable conversions to uniform and
// normal variates (the standard library's distributions differ between implementations; these
// do not, so a seed gives the same files with any standard library).
#pragma once

#include "nao/tools/splitmix.hpp"

#include <cmath>
#include <cstdint>
#include <random>

namespace nao::tools {

class SynthRandom {
 public:
  explicit SynthRandom(std::uint64_t seed) : engine_(seed) {}

  /// Uniform in [0, 1), 53 random bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

  /// Standard normal (Box-Muller, one variate per call).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * 3.14159265358979323846 * u2);
  }
  double normal(double mean, double sd) { return mean + sd * normal(); }

  /// Normal truncated at mean ± k sd (redrawn up to 32 times, then clamped).
  double truncatedNormal(double mean, double sd, double k) {
    for (int i = 0; i < 32; ++i) {
      const double z = normal();
      if (std::abs(z) <= k) return mean + sd * z;
    }
    return mean;
  }

 private:
  std::mt19937_64 engine_;
};

}  // namespace nao::tools
