// k-means++ key poses of robot joint trajectories (paper §3.3, eqs. 7-10, Algorithm 2) and the
// feature-extracted trajectories built from them (DESIGN §6).
#pragma once

#include "nao/arm_model.hpp"

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

/// Index of the centroid nearest to q (Euclidean in joint space; ties go to the lower index).
int nearestCentroid(const std::vector<JointVector>& centroids, const JointVector& q);

/// k-means++ seeding (first centre uniform, then each with probability D(q)^2 / sum D^2) from a
/// local generator seeded with options.seed, then rounds of "assign to nearest, update each
/// centroid" until a round changes no assignment or max_iterations. A centroid left without
/// members is moved to the point farthest from its own centroid. Deterministic for a seed.
/// Throws UserError for k < 1 or fewer points than k.
KMeansResult kmeansPlusPlus(const std::vector<JointVector>& points, const KMeansOptions& options);

/// Feature-extracted trajectory (DESIGN §6): the samples are labelled by nearest centroid; each
/// run of equal labels is a segment whose key pose is its centroid, placed at the segment's
/// middle; consecutive key poses are joined with a smoothstep blend, the first and last held
/// to the ends. One output pose per input sample, same timing.
std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q);

/// As above, with the segments taken from the measured samples (t_s, q) and the trajectory
/// evaluated at the times t_eval (e.g. the whole 10 Hz grid, including samples where no human
/// was measured): one output pose per entry of t_eval.
std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q, const std::vector<double>& t_eval);

}  // namespace nao::tools
