// Whether a rollout makes the movement (docs/evaluate.md): measures of a hand path that DTW to
// the nearest demonstration does not see - how fast the hand moves in the movement's middle, how
// many loops it draws there, which runs are near-copies of another, and the medoid of a set of
// demonstrations. Offline code: allocates, may throw.
#pragma once

#include "nao/arm_model.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace nao::tools {

using HandPath = std::vector<Eigen::Vector3d>;

/// The middle stretch of a path of n points: indices [floor(0.2 n), ceil(0.8 n)) - the middle
/// 60 % of its duration, where a demonstration is in its movement rather than raising or
/// lowering the arm. Empty for n < 2.
struct Stretch {
  std::size_t begin = 0, end = 0;
};
Stretch middleStretch(std::size_t n);

/// RMS hand speed over the middle stretch, m/s: the root mean square of |p(i+1) − p(i)| / period
/// over consecutive points of the stretch. NaN when the stretch has fewer than 2 points.
double middleRmsSpeed(const HandPath& path, double period_s);

/// The plane loops are counted in: the first two principal directions (unit, torso frame) of the
/// middle-stretch points of `paths`, each stretch centred on its own centroid first (so where a
/// demonstration circles does not matter, only in which plane). Throws UserError when the points
/// span no plane (fewer than 3 points in all, or all on a line).
Eigen::Matrix<double, 3, 2> loopPlane(const std::vector<HandPath>& paths);

/// Loops drawn over the middle stretch: |Σ Δθ| / 2π, θ the unwrapped angle of each point of the
/// stretch around the stretch's own centroid, in `plane`. Turning back and forth cancels out;
/// 0 for a stretch of fewer than 2 points.
double loopCount(const HandPath& path, const Eigen::Matrix<double, 3, 2>& plane);

/// Number of runs that are distinct: whose hand-path DTW (rt::dtwMeanDistance) to every other run
/// is at least `min_distance_m`. 0 or 1 runs: all distinct.
std::size_t distinctRuns(const std::vector<HandPath>& runs, double min_distance_m = 1e-3);

/// Index (into `paths`) of the medoid of the listed paths: the one with the smallest summed DTW
/// to the others (ties to the earlier entry of `members`). Throws UserError for an empty list.
int medoid(const std::vector<HandPath>& paths, const std::vector<int>& members);

/// The `k` entries of `starts` nearest `q` (Euclidean over the joint angles, rad; ties to the
/// lower index), nearest first; all of them when there are fewer.
std::vector<int> nearestStarts(const std::vector<JointVector>& starts, const JointVector& q, std::size_t k);

/// RMS over the elements of a sequence of joint vectors (rad): sqrt(mean of squares over every
/// tick and joint). 0 for an empty sequence.
double rmsOf(const std::vector<JointVector>& v);

}  // namespace nao::tools
