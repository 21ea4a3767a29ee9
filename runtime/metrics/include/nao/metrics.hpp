// The run-level measures (nao_metrics): latency percentiles and the hand-path distances, which
// nao_rt writes into summary.json and the evaluation scores runs by. Runs after the loop, allocates.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace nao::rt {

/// p50 / p99 / max of a latency column, µs.
struct LatencyStats {
  double p50 = 0.0;
  double p99 = 0.0;
  double max = 0.0;
};

/// Nearest-rank percentiles (p50 = the ceil(0.50 n)-th smallest value, p99 = the ceil(0.99 n)-th)
/// and the maximum of `values`; all 0 for an empty input.
LatencyStats latencyStats(std::vector<double> values);

/// Dynamic-time-warping distance between two paths of points (e.g. hand positions in m, torso
/// frame): the minimum-cost monotone alignment of every point of `a` with every point of `b`
/// (steps (1,0), (0,1), (1,1); point cost = Euclidean distance), divided by the number of
/// matched pairs on that alignment, so it is a mean distance per matched pair, in the points'
/// unit. Among alignments of equal cost the one with more pairs wins (ties: diagonal first).
/// Identical paths give 0, a path and its copy shifted by a constant vector of length d give d,
/// and a time-warped copy (points repeated or dropped in place) gives 0. O(|a|·|b|) time,
/// O(|b|) memory. Returns NaN if either path is empty.
double dtwMeanDistance(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b);

}  // namespace nao::rt
