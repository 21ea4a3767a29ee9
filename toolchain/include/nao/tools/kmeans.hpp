// k-means++ key poses of robot joint trajectories (paper §3.3, eqs. 7-10, Algorithm 2) and the
// feature-extracted trajectories built from them (docs/formats.md "Key poses").
#pragma once

#include "nao/arm_model.hpp"
#include "nao/feature_trajectory.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

enum class CentroidUpdate {
  kMean,    ///< Lloyd's update, paper eq. 10 (minimises F of eq. 7)
  kMedian,  ///< per-joint median of the members, paper Algorithm 2
};

struct KMeansOptions {
  int k = 10;                 ///< number of key poses (paper: 10)
  CentroidUpdate update = CentroidUpdate::kMean;
  std::uint64_t seed = 1;     ///< seeds the k-means++ draws
  int max_iterations = 300;   ///< cap on assignment/update rounds
};

struct KMeansResult {
  std::vector<JointVector> centroids;  ///< k key poses, rad
  std::vector<int> labels;             ///< nearest centroid of every point
  double objective = 0.0;              ///< F of eq. 7: sum of squared distances to the own centroid, rad^2
  int iterations = 0;                  ///< assignment/update rounds run
  bool converged = false;              ///< true: a round changed no assignment (false: cap hit)
};

/// k-means++ seeding (first centre uniform, then each with probability D(q)^2 / sum D^2) from a
/// local generator seeded with options.seed, then rounds of "assign to nearest, update each
/// centroid" until a round changes no assignment or max_iterations. A centroid left without
/// members is moved to the point farthest from its own centroid. Deterministic for a seed.
/// Throws UserError for k < 1 or fewer points than k.
KMeansResult kmeansPlusPlus(const std::vector<JointVector>& points, const KMeansOptions& options);

// Key-pose snapping and the feature-extracted trajectory are the runtime's
// (nao/feature_trajectory.hpp): nao_rt scores a recorded reference against it.
using nao::featureTrajectory;
using nao::KeyPoseBlend;
using nao::keyPoseLabels;
using nao::nearestCentroid;

}  // namespace nao::tools
