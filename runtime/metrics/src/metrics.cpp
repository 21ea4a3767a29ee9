#include "nao/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao::rt {

LatencyStats latencyStats(std::vector<double> values) {
  LatencyStats s;
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  auto rank = [&](double p) {
    const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(n)));
    return values[std::clamp<std::size_t>(k, 1, n) - 1];
  };
  s.p50 = rank(0.50);
  s.p99 = rank(0.99);
  s.max = values.back();
  return s;
}

double dtwMeanDistance(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  if (a.empty() || b.empty()) return std::numeric_limits<double>::quiet_NaN();
  const std::size_t m = b.size();
  // Two rows of the cumulative cost and of the pair count of the best alignment ending in
  // each cell; row i covers a[i] against every b[j].
  std::vector<double> cost_prev(m), cost(m);
  std::vector<std::size_t> len_prev(m), len(m);
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < m; ++j) {
      const double d = (a[i] - b[j]).norm();
      if (i == 0 && j == 0) {
        cost[j] = d;
        len[j] = 1;
        continue;
      }
      // Candidates: diagonal, then up (i-1, j), then left (i, j-1); lower cost wins, then more
      // pairs (a longer alignment of equal total cost has the lower mean).
      double best = std::numeric_limits<double>::infinity();
      std::size_t best_len = 0;
      auto consider = [&](double c, std::size_t l) {
        if (c < best || (c == best && l > best_len)) {
          best = c;
          best_len = l;
        }
      };
      if (i > 0 && j > 0) consider(cost_prev[j - 1], len_prev[j - 1]);
      if (i > 0) consider(cost_prev[j], len_prev[j]);
      if (j > 0) consider(cost[j - 1], len[j - 1]);
      cost[j] = best + d;
      len[j] = best_len + 1;
    }
    std::swap(cost, cost_prev);
    std::swap(len, len_prev);
  }
  return cost_prev[m - 1] / static_cast<double>(len_prev[m - 1]);
}

}  // namespace nao::rt
