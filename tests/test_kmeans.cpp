// k-means++ key poses: checked against properties computed independently of the code under test.
#include "nao/tools/command.hpp"
#include "nao/tools/kmeans.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace nao;
using namespace nao::tools;

namespace {

// n points around each of the given centres, Gaussian with standard deviation sigma (rad).
std::vector<JointVector> blobs(const std::vector<JointVector>& centres, int n, double sigma, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<JointVector> out;
  for (int i = 0; i < n; ++i)
    for (const JointVector& c : centres) {
      JointVector p = c;
      for (int j = 0; j < kNumJoints; ++j) p[j] += noise(rng);
      out.push_back(p);
    }
  return out;
}

std::vector<JointVector> randomCentres(int k, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::vector<JointVector> c(static_cast<std::size_t>(k));
  for (JointVector& v : c)
    for (int j = 0; j < kNumJoints; ++j) v[j] = u(rng);
  return c;
}

}  // namespace

TEST_CASE("k-means++ finds well-separated key poses: every true centre has a centroid within 0.02 rad") {
  const std::vector<JointVector> truth = randomCentres(10, 3);
  // Separation check of the fixture itself: the centres must be far apart for the claim to hold.
  for (std::size_t a = 0; a < truth.size(); ++a)
    for (std::size_t b = a + 1; b < truth.size(); ++b) REQUIRE((truth[a] - truth[b]).norm() > 0.3);
  const std::vector<JointVector> points = blobs(truth, 60, 0.01, 4);
  KMeansOptions options;
  const KMeansResult r = kmeansPlusPlus(points, options);
  REQUIRE(r.converged);
  for (const JointVector& c : truth) {
    double best = 1e9;
    for (const JointVector& m : r.centroids) best = std::min(best, (m - c).norm());
    CHECK_MESSAGE(best < 0.02, "true centre " << c.transpose() << " has no centroid nearer than " << best);
  }
}

TEST_CASE("at convergence every mean centroid is the mean of its members and every point is labelled nearest") {
  const std::vector<JointVector> points = blobs(randomCentres(6, 11), 40, 0.3, 12);  // overlapping: a real fit
  KMeansOptions options;
  options.k = 10;
  const KMeansResult r = kmeansPlusPlus(points, options);
  REQUIRE(r.converged);
  double objective = 0.0;
  for (int c = 0; c < options.k; ++c) {
    JointVector sum = JointVector::Zero();
    int n = 0;
    for (std::size_t i = 0; i < points.size(); ++i)
      if (r.labels[i] == c) {
        sum += points[i];
        ++n;
      }
    REQUIRE(n > 0);
    CHECK((r.centroids[static_cast<std::size_t>(c)] - sum / n).cwiseAbs().maxCoeff() < 1e-12);
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    const int label = r.labels[i];
    objective += (points[i] - r.centroids[static_cast<std::size_t>(label)]).squaredNorm();
    for (const JointVector& m : r.centroids)
      CHECK((points[i] - r.centroids[static_cast<std::size_t>(label)]).squaredNorm() <= (points[i] - m).squaredNorm());
  }
  CHECK(r.objective == doctest::Approx(objective).epsilon(1e-12));
}

TEST_CASE("the median update (paper Algorithm 2) makes each centroid the per-joint median of its members") {
  const std::vector<JointVector> points = blobs(randomCentres(4, 21), 25, 0.2, 22);
  KMeansOptions options;
  options.k = 4;
  options.update = CentroidUpdate::kMedian;
  const KMeansResult r = kmeansPlusPlus(points, options);
  REQUIRE(r.converged);
  for (int c = 0; c < options.k; ++c)
    for (int j = 0; j < kNumJoints; ++j) {
      std::vector<double> v;
      for (std::size_t i = 0; i < points.size(); ++i)
        if (r.labels[i] == c) v.push_back(points[i][j]);
      REQUIRE(!v.empty());
      // Median by partial selection, not by the code's sort.
      const std::size_t mid = v.size() / 2;
      std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
      double median = v[mid];
      if (v.size() % 2 == 0) median = 0.5 * (median + *std::max_element(v.begin(), v.begin() + static_cast<long>(mid)));
      CHECK(r.centroids[static_cast<std::size_t>(c)][j] == doctest::Approx(median).epsilon(1e-12));
    }
}

TEST_CASE("k-means++ is deterministic for a seed and depends on it") {
  const std::vector<JointVector> points = blobs(randomCentres(8, 31), 30, 0.4, 32);
  KMeansOptions options;
  const KMeansResult a = kmeansPlusPlus(points, options);
  const KMeansResult b = kmeansPlusPlus(points, options);
  CHECK(a.labels == b.labels);
  for (std::size_t c = 0; c < a.centroids.size(); ++c) CHECK(a.centroids[c] == b.centroids[c]);
  options.seed = 99;
  const KMeansResult other = kmeansPlusPlus(points, options);
  bool differs = false;
  for (std::size_t c = 0; c < a.centroids.size(); ++c) differs |= !(a.centroids[c] == other.centroids[c]);
  CHECK_MESSAGE(differs, "another seed gave exactly the same centroids");
}

TEST_CASE("k-means refuses fewer points than clusters and k below 1") {
  const std::vector<JointVector> points(3, JointVector::Zero());
  KMeansOptions options;
  options.k = 4;
  CHECK_THROWS_WITH_AS(kmeansPlusPlus(points, options), doctest::Contains("cannot make 4 clusters"), UserError);
  options.k = 0;
  CHECK_THROWS_AS(kmeansPlusPlus(points, options), UserError);
}

TEST_CASE("after a key-pose change the feature-extracted trajectory follows the closed form of the blend") {
  // Three plateaus of 11 samples at 10 Hz (the centroids are the plateau values). From rest at
  // c0, a switch to c1 at tick s gives f(s + n) - c1 = (c0 - c1) (1 + (1 - p) n) p^n: the
  // critically damped double pole, worked out independently of the recurrence.
  const std::vector<JointVector> centroids = {JointVector::Constant(0.0), JointVector::Constant(1.0),
                                              JointVector::Constant(-0.5)};
  std::vector<double> t;
  std::vector<JointVector> q;
  for (int i = 0; i < 33; ++i) {
    t.push_back(0.1 * i);
    q.push_back(centroids[static_cast<std::size_t>(i / 11)] + JointVector::Constant(0.01 * ((i % 3) - 1)));
  }
  KeyPoseBlend blend;
  blend.pole = 0.7;
  const std::vector<JointVector> f = featureTrajectory(centroids, t, q, blend);
  REQUIRE(f.size() == q.size());
  for (int i = 0; i <= 11; ++i) CHECK(f[static_cast<std::size_t>(i)] == centroids[0]);  // at rest until the switch
  const double p = blend.pole;
  for (int n = 0; n < 11; ++n) {
    const double expected = 1.0 + (0.0 - 1.0) * (1.0 + (1.0 - p) * n) * std::pow(p, n);
    CHECK(f[static_cast<std::size_t>(11 + n)][0] == doctest::Approx(expected).epsilon(1e-12));
    // Critically damped: it approaches the new key pose without overshoot.
    if (n > 0) CHECK(f[static_cast<std::size_t>(11 + n)][0] >= f[static_cast<std::size_t>(10 + n)][0]);
    CHECK(f[static_cast<std::size_t>(11 + n)][0] <= 1.0);
  }
  // The recurrence is the blend: f(t+1) - f(t) = velocity(f(t) - f(t-1), f(t), c(t)).
  const std::vector<int> labels = keyPoseLabels(centroids, t, q, t);
  for (std::size_t i = 1; i + 1 < f.size(); ++i) {
    const JointVector v = blend.velocity(f[i] - f[i - 1], f[i], centroids[static_cast<std::size_t>(labels[i])]);
    CHECK((f[i + 1] - f[i] - v).cwiseAbs().maxCoeff() < 1e-12);
  }
}

TEST_CASE("the feature-extracted trajectory is causal: later samples never change earlier poses") {
  const std::vector<JointVector> centroids = {JointVector::Constant(0.0), JointVector::Constant(1.0),
                                              JointVector::Constant(-0.5)};
  std::vector<double> t;
  std::vector<JointVector> q;
  for (int i = 0; i < 40; ++i) {
    t.push_back(0.1 * i);
    q.push_back(centroids[static_cast<std::size_t>((i / 7) % 3)]);
  }
  const std::vector<JointVector> full = featureTrajectory(centroids, t, q);
  for (std::size_t k : {1u, 8u, 15u, 29u}) {
    const std::vector<double> t_k(t.begin(), t.begin() + static_cast<std::ptrdiff_t>(k));
    const std::vector<JointVector> q_k(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(k));
    const std::vector<JointVector> part = featureTrajectory(centroids, t_k, q_k);
    for (std::size_t i = 0; i < k; ++i) CHECK(part[i] == full[i]);
  }
}

TEST_CASE("on a grid with unmeasured samples the last measured key pose stays in force") {
  // Every 4th sample is not measured. Cross-check: the same as evaluating a fully measured
  // grid in which each unmeasured sample repeats the last measured pose.
  const std::vector<JointVector> centroids = {JointVector::Constant(0.0), JointVector::Constant(1.0),
                                              JointVector::Constant(-0.5)};
  std::vector<double> t_grid, t_meas;
  std::vector<JointVector> q_meas, q_filled;
  for (int i = 0; i < 33; ++i) {
    t_grid.push_back(0.1 * i);
    const JointVector qi = centroids[static_cast<std::size_t>((i / 3) % 3)];
    if (i % 4 == 3) {
      q_filled.push_back(q_filled.back());
      continue;
    }
    t_meas.push_back(0.1 * i);
    q_meas.push_back(qi);
    q_filled.push_back(qi);
  }
  const std::vector<JointVector> f_grid = featureTrajectory(centroids, t_meas, q_meas, t_grid);
  const std::vector<JointVector> f_filled = featureTrajectory(centroids, t_grid, q_filled);
  REQUIRE(f_grid.size() == t_grid.size());
  for (std::size_t i = 0; i < t_grid.size(); ++i) CHECK(f_grid[i] == f_filled[i]);
  // Before the first measured sample the first key pose is in force.
  const std::vector<int> labels = keyPoseLabels(centroids, {0.25}, {centroids[2]}, {0.0, 0.1, 0.2, 0.3});
  CHECK(labels == std::vector<int>{2, 2, 2, 2});
  CHECK_THROWS_AS(featureTrajectory(centroids, {}, {}, t_grid), UserError);
  CHECK_THROWS_WITH_AS(featureTrajectory(centroids, t_meas, q_meas, {0.0, 0.2, 0.1}),
                       doctest::Contains("must increase"), UserError);
}
