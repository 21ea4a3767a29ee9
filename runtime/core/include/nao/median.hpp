// The median, shared by the runtime's configure-time statistics (the human scale of a recorded
// demonstration) and the toolchain's summaries.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace nao {

/// Median of `v` (the mean of the two middle values for an even count); 0 for an empty `v`.
/// Takes a copy: nth_element reorders it.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  const double lower = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
  return 0.5 * (lower + upper);
}

}  // namespace nao
