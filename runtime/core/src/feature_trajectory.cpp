// Key-pose snapping and the feature-extracted trajectory (nao/feature_trajectory.hpp).
#include "nao/feature_trajectory.hpp"

#include "nao/input_error.hpp"

#include <limits>
#include <string>

namespace nao {

int nearestCentroid(const std::vector<JointVector>& centroids, const JointVector& q) {
  int best = 0;
  double best_d = std::numeric_limits<double>::infinity();
  for (std::size_t c = 0; c < centroids.size(); ++c) {
    const double d = (centroids[c] - q).squaredNorm();
    if (d < best_d) {
      best_d = d;
      best = static_cast<int>(c);
    }
  }
  return best;
}

std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q, const KeyPoseBlend& blend) {
  return featureTrajectory(centroids, t_s, q, t_s, blend);
}

std::vector<int> keyPoseLabels(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                               const std::vector<JointVector>& q, const std::vector<double>& t_eval) {
  if (t_s.size() != q.size()) throw InputError("featureTrajectory: times and poses differ in length");
  std::vector<int> labels(t_eval.size());
  if (t_eval.empty()) return labels;
  if (q.empty()) throw InputError("featureTrajectory: no measured samples to build segments from");
  // A sample counts from its own tick on (0.1 ms of slack for times rounded in a CSV); before
  // the first measured sample the first key pose is in force.
  constexpr double kSlack = 1e-4;
  std::size_t m = 0;
  int label = nearestCentroid(centroids, q[0]);
  for (std::size_t i = 0; i < t_eval.size(); ++i) {
    if (i > 0 && !(t_eval[i] > t_eval[i - 1]))
      throw InputError("featureTrajectory: evaluation times must increase (sample " + std::to_string(i) + ")");
    while (m < q.size() && t_s[m] <= t_eval[i] + kSlack) label = nearestCentroid(centroids, q[m++]);
    labels[i] = label;
  }
  return labels;
}

std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q, const std::vector<double>& t_eval,
                                           const KeyPoseBlend& blend) {
  const std::vector<int> labels = keyPoseLabels(centroids, t_s, q, t_eval);
  std::vector<JointVector> out(t_eval.size());
  if (out.empty()) return out;
  JointVector f = centroids[static_cast<std::size_t>(labels[0])];
  JointVector v = JointVector::Zero();
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i] = f;
    v = blend.velocity(v, f, centroids[static_cast<std::size_t>(labels[i])]);
    f += v;
  }
  return out;
}

}  // namespace nao
