// splitmix64 (Steele, Lea, Flood 2014): the toolchain's one seeded generator whose output is the
// same on every platform and standard library (std distributions are implementation-defined).
#pragma once

#include <cmath>
#include <cstdint>

namespace nao::tools {

/// The splitmix64 finaliser of x + golden gamma: decorrelates seeds derived from small integers
/// (one step of SplitMix64 from state x).
inline std::uint64_t splitMix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

/// The generator: each next() is splitMix64 of the advancing state.
class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    const std::uint64_t z = splitMix64(state_);
    state_ += 0x9e3779b97f4a7c15ULL;
    return z;
  }
  /// Uniform in 0..n-1 without modulo bias (rejection of the incomplete last block).
  std::uint64_t below(std::uint64_t n) {
    const std::uint64_t threshold = (0 - n) % n;
    for (;;) {
      const std::uint64_t r = next();
      if (r >= threshold) return r % n;
    }
  }
  /// Uniform in (0, 1), 53 random bits.
  double uniform() { return (static_cast<double>(next() >> 11) + 0.5) * 0x1.0p-53; }
  /// Standard normal (Box-Muller, one variate per call).
  double normal() {
    const double u1 = uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * 3.14159265358979323846 * u2);
  }

 private:
  std::uint64_t state_;
};

}  // namespace nao::tools
