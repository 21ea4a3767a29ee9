// k-means++ key poses: checked against properties computed independently of the code under test.
#include "nao/tools/command.hpp"
#include "nao/tools/kmeans.hpp"

#include <doctest/doctest.h>

#include <algorithm>
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

TEST_CASE("the feature-extracted trajectory passes through each segment's key pose at the segment's middle") {
  // Three plateaus of 11 samples at 10 Hz, so each segment's middle falls on a sample
  // (0.5 s, 1.6 s, 2.7 s); the centroids are the plateau values.
  std::vector<JointVector> centroids = {JointVector::Constant(0.0), JointVector::Constant(1.0),
                                        JointVector::Constant(-0.5)};
  std::vector<double> t;
  std::vector<JointVector> q;
  for (int i = 0; i < 33; ++i) {
    t.push_back(0.1 * i);
    q.push_back(centroids[static_cast<std::size_t>(i / 11)] + JointVector::Constant(0.01 * ((i % 3) - 1)));
  }
  const std::vector<JointVector> f = featureTrajectory(centroids, t, q);
  REQUIRE(f.size() == q.size());
  CHECK(f[5] == centroids[0]);
  CHECK(f[16] == centroids[1]);
  CHECK(f[27] == centroids[2]);
  // Held before the first middle and after the last.
  CHECK(f[0] == centroids[0]);
  CHECK(f[32] == centroids[2]);
  // Between key poses the blend stays between them and moves monotonically.
  for (int i = 5; i < 16; ++i) {
    CHECK(f[static_cast<std::size_t>(i)][0] >= 0.0);
    CHECK(f[static_cast<std::size_t>(i)][0] <= 1.0);
    CHECK(f[static_cast<std::size_t>(i + 1)][0] >= f[static_cast<std::size_t>(i)][0]);
  }
}

TEST_CASE("the feature-extracted trajectory on a grid with unmeasured samples equals the measured-only one where both exist") {
  // Same plateaus as above on a 10 Hz grid; every 4th sample is "not measured" and left out of
  // the segments. Evaluated on the whole grid, the measured times must give the poses of the
  // measured-only trajectory, and unmeasured times lie on the same smooth blend.
  std::vector<JointVector> centroids = {JointVector::Constant(0.0), JointVector::Constant(1.0),
                                        JointVector::Constant(-0.5)};
  std::vector<double> t_grid, t_meas;
  std::vector<JointVector> q_meas;
  for (int i = 0; i < 33; ++i) {
    t_grid.push_back(0.1 * i);
    if (i % 4 == 3) continue;
    t_meas.push_back(0.1 * i);
    q_meas.push_back(centroids[static_cast<std::size_t>(i / 11)]);
  }
  const std::vector<JointVector> f_meas = featureTrajectory(centroids, t_meas, q_meas);
  const std::vector<JointVector> f_grid = featureTrajectory(centroids, t_meas, q_meas, t_grid);
  REQUIRE(f_grid.size() == t_grid.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < t_grid.size(); ++i) {
    if (i % 4 == 3) continue;
    CHECK(f_grid[i] == f_meas[k++]);
  }
  // An unmeasured sample between two measured ones on a monotone blend lies between them.
  for (std::size_t i = 3; i + 1 < t_grid.size(); i += 4) {
    const double lo = std::min(f_grid[i - 1][0], f_grid[i + 1][0]);
    const double hi = std::max(f_grid[i - 1][0], f_grid[i + 1][0]);
    CHECK(f_grid[i][0] >= lo);
    CHECK(f_grid[i][0] <= hi);
  }
  CHECK_THROWS_AS(featureTrajectory(centroids, {}, {}, t_grid), UserError);
}
