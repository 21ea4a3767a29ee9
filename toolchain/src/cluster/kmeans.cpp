#include "nao/tools/kmeans.hpp"

#include "nao/tools/command.hpp"

#include <algorithm>
#include <random>
#include <string>

namespace nao::tools {
namespace {

// Uniform double in [0, 1) from the generator's raw bits: the same on every standard library
// (std::uniform_real_distribution's algorithm is left to the implementation).
double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

double squaredDistance(const JointVector& a, const JointVector& b) { return (a - b).squaredNorm(); }

JointVector medianOf(const std::vector<JointVector>& points, const std::vector<int>& labels, int cluster,
                     std::vector<double>& scratch) {
  JointVector m;
  for (int j = 0; j < kNumJoints; ++j) {
    scratch.clear();
    for (std::size_t i = 0; i < points.size(); ++i)
      if (labels[i] == cluster) scratch.push_back(points[i][j]);
    std::sort(scratch.begin(), scratch.end());
    const std::size_t n = scratch.size();
    m[j] = n % 2 == 1 ? scratch[n / 2] : 0.5 * (scratch[n / 2 - 1] + scratch[n / 2]);
  }
  return m;
}

}  // namespace

KMeansResult kmeansPlusPlus(const std::vector<JointVector>& points, const KMeansOptions& options) {
  const int k = options.k;
  if (k < 1) throw UserError("k-means: k must be at least 1, got " + std::to_string(k));
  if (points.size() < static_cast<std::size_t>(k))
    throw UserError("k-means: " + std::to_string(points.size()) + " points cannot make " + std::to_string(k) +
                    " clusters");
  const std::size_t n = points.size();
  std::mt19937_64 rng(options.seed);
  KMeansResult r;

  // Seeding (Algorithm 2, first loop): D(q)^2 weighting of the distance to the nearest centre.
  r.centroids.push_back(points[static_cast<std::size_t>(uniform01(rng) * static_cast<double>(n))]);
  std::vector<double> d2(n);
  for (std::size_t i = 0; i < n; ++i) d2[i] = squaredDistance(points[i], r.centroids[0]);
  while (r.centroids.size() < static_cast<std::size_t>(k)) {
    double total = 0.0;
    for (double v : d2) total += v;
    std::size_t pick = n - 1;
    if (total > 0.0) {
      const double u = uniform01(rng) * total;
      double acc = 0.0;
      for (std::size_t i = 0; i < n; ++i) {
        acc += d2[i];
        if (u < acc) {
          pick = i;
          break;
        }
      }
    } else {
      pick = static_cast<std::size_t>(uniform01(rng) * static_cast<double>(n));  // all points coincide
    }
    r.centroids.push_back(points[pick]);
    for (std::size_t i = 0; i < n; ++i) d2[i] = std::min(d2[i], squaredDistance(points[i], r.centroids.back()));
  }

  // Rounds of assignment (eq. 9) and update (eq. 10 or the median of Algorithm 2).
  r.labels.assign(n, -1);
  std::vector<double> scratch;
  for (r.iterations = 0; r.iterations < options.max_iterations;) {
    bool changed = false;
    for (std::size_t i = 0; i < n; ++i) {
      const int c = nearestCentroid(r.centroids, points[i]);
      changed |= c != r.labels[i];
      r.labels[i] = c;
    }
    ++r.iterations;
    if (!changed) {
      r.converged = true;
      break;
    }
    std::vector<int> count(static_cast<std::size_t>(k), 0);
    std::vector<JointVector> sum(static_cast<std::size_t>(k), JointVector::Zero());
    for (std::size_t i = 0; i < n; ++i) {
      ++count[static_cast<std::size_t>(r.labels[i])];
      sum[static_cast<std::size_t>(r.labels[i])] += points[i];
    }
    for (int c = 0; c < k; ++c) {
      const auto cu = static_cast<std::size_t>(c);
      if (count[cu] == 0) {
        // Empty cluster: take over the point worst served by its own centroid.
        std::size_t far = 0;
        double far_d = -1.0;
        for (std::size_t i = 0; i < n; ++i) {
          const double d = squaredDistance(points[i], r.centroids[static_cast<std::size_t>(r.labels[i])]);
          if (d > far_d) {
            far_d = d;
            far = i;
          }
        }
        r.centroids[cu] = points[far];
        r.labels[far] = c;
        continue;
      }
      r.centroids[cu] = options.update == CentroidUpdate::kMean ? JointVector(sum[cu] / count[cu])
                                                                 : medianOf(points, r.labels, c, scratch);
    }
  }
  r.objective = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    r.objective += squaredDistance(points[i], r.centroids[static_cast<std::size_t>(r.labels[i])]);
  return r;
}

}  // namespace nao::tools
