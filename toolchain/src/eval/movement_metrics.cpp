#include "nao/tools/movement_metrics.hpp"

#include "nao/tools/command.hpp"
#include "nao/metrics.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace nao::tools {

Stretch middleStretch(std::size_t n) {
  if (n < 2) return {};
  const auto begin = static_cast<std::size_t>(std::floor(0.2 * static_cast<double>(n)));
  const auto end = std::min(n, static_cast<std::size_t>(std::ceil(0.8 * static_cast<double>(n))));
  return {begin, end};
}

double middleRmsSpeed(const HandPath& path, double period_s) {
  const Stretch s = middleStretch(path.size());
  if (s.end < s.begin + 2) return std::numeric_limits<double>::quiet_NaN();
  double sum = 0.0;
  for (std::size_t i = s.begin; i + 1 < s.end; ++i) sum += (path[i + 1] - path[i]).squaredNorm();
  return std::sqrt(sum / static_cast<double>(s.end - s.begin - 1)) / period_s;
}

namespace {

Eigen::Vector3d centroidOf(const HandPath& path, Stretch s) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (std::size_t i = s.begin; i < s.end; ++i) c += path[i];
  return c / static_cast<double>(s.end - s.begin);
}

}  // namespace

Eigen::Matrix<double, 3, 2> loopPlane(const std::vector<HandPath>& paths) {
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  std::size_t n = 0;
  for (const HandPath& p : paths) {
    const Stretch s = middleStretch(p.size());
    if (s.end <= s.begin) continue;
    const Eigen::Vector3d c = centroidOf(p, s);
    for (std::size_t i = s.begin; i < s.end; ++i) scatter += (p[i] - c) * (p[i] - c).transpose();
    n += s.end - s.begin;
  }
  // Eigenvalues in increasing order: the plane is spanned by the last two eigenvectors.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  if (n < 3 || !(eig.eigenvalues()(1) > 1e-12 * std::max(1.0, eig.eigenvalues()(2))))
    throw UserError("the demonstrations' middle stretches span no plane to count loops in");
  Eigen::Matrix<double, 3, 2> plane;
  plane.col(0) = eig.eigenvectors().col(2);
  plane.col(1) = eig.eigenvectors().col(1);
  return plane;
}

double loopCount(const HandPath& path, const Eigen::Matrix<double, 3, 2>& plane) {
  const Stretch s = middleStretch(path.size());
  if (s.end < s.begin + 2) return 0.0;
  const Eigen::Vector3d c = centroidOf(path, s);
  double total = 0.0, prev = 0.0;
  for (std::size_t i = s.begin; i < s.end; ++i) {
    const Eigen::Vector2d p = plane.transpose() * (path[i] - c);
    const double theta = std::atan2(p.y(), p.x());
    if (i > s.begin) {
      // Unwrapped: each step is taken as the turn of less than half a circle.
      double d = theta - prev;
      d -= 2.0 * M_PI * std::round(d / (2.0 * M_PI));
      total += d;
    }
    prev = theta;
  }
  return std::abs(total) / (2.0 * M_PI);
}

std::size_t distinctRuns(const std::vector<HandPath>& runs, double min_distance_m) {
  std::vector<bool> copy(runs.size(), false);
  for (std::size_t i = 0; i < runs.size(); ++i)
    for (std::size_t j = i + 1; j < runs.size(); ++j)
      if (rt::dtwMeanDistance(runs[i], runs[j]) < min_distance_m) copy[i] = copy[j] = true;
  return static_cast<std::size_t>(std::count(copy.begin(), copy.end(), false));
}

int medoid(const std::vector<HandPath>& paths, const std::vector<int>& members) {
  if (members.empty()) throw UserError("medoid of no demonstration");
  int best = members.front();
  double best_sum = std::numeric_limits<double>::infinity();
  for (int i : members) {
    double sum = 0.0;
    for (int j : members)
      if (j != i) sum += rt::dtwMeanDistance(paths.at(static_cast<std::size_t>(i)), paths.at(static_cast<std::size_t>(j)));
    if (sum < best_sum) {
      best_sum = sum;
      best = i;
    }
  }
  return best;
}

std::vector<int> nearestStarts(const std::vector<JointVector>& starts, const JointVector& q, std::size_t k) {
  std::vector<int> order(starts.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return (starts[static_cast<std::size_t>(a)] - q).squaredNorm() < (starts[static_cast<std::size_t>(b)] - q).squaredNorm();
  });
  if (order.size() > k) order.resize(k);
  return order;
}

double rmsOf(const std::vector<JointVector>& v) {
  if (v.empty()) return 0.0;
  double sum = 0.0;
  for (const JointVector& x : v) sum += x.squaredNorm();
  return std::sqrt(sum / static_cast<double>(v.size() * static_cast<std::size_t>(kNumJoints)));
}

}  // namespace nao::tools
