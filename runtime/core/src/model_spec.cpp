// The choice of a run's code (nao/model_spec.hpp: runCodeIndex, runCode).
#include "nao/model_spec.hpp"

#include <algorithm>
#include <array>
#include <limits>

namespace nao {

int runCodeIndex(const ModelRunCodes& codes, const JointVector& q0, int exclude) {
  const int n = static_cast<int>(codes.size());
  if (n == 0 || (n == 1 && exclude == 0)) return -1;
  // The nearest starts in order of distance, a stable insertion: equal distances keep index order.
  std::array<int, kRunCodeNearest> near{};
  std::array<double, kRunCodeNearest> dist{};
  int k = 0;
  for (int i = 0; i < n; ++i) {
    if (i == exclude) continue;
    const double di = (codes.q[static_cast<std::size_t>(i)] - q0).squaredNorm();
    if (k == kRunCodeNearest && !(di < dist[kRunCodeNearest - 1])) continue;
    int at = std::min(k, kRunCodeNearest - 1);
    while (at > 0 && di < dist[static_cast<std::size_t>(at - 1)]) {
      near[static_cast<std::size_t>(at)] = near[static_cast<std::size_t>(at - 1)];
      dist[static_cast<std::size_t>(at)] = dist[static_cast<std::size_t>(at - 1)];
      --at;
    }
    near[static_cast<std::size_t>(at)] = i;
    dist[static_cast<std::size_t>(at)] = di;
    k = std::min(k + 1, kRunCodeNearest);
  }
  int best = near[0];
  double best_sum = std::numeric_limits<double>::infinity();
  for (int a = 0; a < k; ++a) {
    double sum = 0.0;
    for (int b = 0; b < k; ++b)
      sum += codes.dtw_m[static_cast<std::size_t>(near[static_cast<std::size_t>(a)]) * codes.size() +
                         static_cast<std::size_t>(near[static_cast<std::size_t>(b)])];
    if (sum < best_sum) {
      best_sum = sum;
      best = near[static_cast<std::size_t>(a)];
    }
  }
  return best;
}

const float* runCode(const std::vector<ModelRunCodes>& codes, int movement, const JointVector& q0, int* index) {
  const bool has = movement >= 0 && static_cast<std::size_t>(movement) < codes.size();
  const ModelRunCodes* c = has ? &codes[static_cast<std::size_t>(movement)] : nullptr;
  const int i = c != nullptr ? runCodeIndex(*c, q0) : -1;
  if (index != nullptr) *index = i;
  return i < 0 ? nullptr : c->code.data() + static_cast<std::size_t>(i) * static_cast<std::size_t>(c->d);
}

}  // namespace nao
