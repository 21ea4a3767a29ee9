// Run-level metrics of nao_rt (nao_metrics): the DTW hand-path distance and latency percentiles.
#include "nao/metrics.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <vector>

using nao::rt::dtwMeanDistance;
using nao::rt::latencyStats;
using Path = std::vector<Eigen::Vector3d>;

namespace {

// A circle of radius r (m) sampled at n points, like a hand path.
Path circle(int n, double r = 0.1) {
  Path p;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * 3.14159265358979323846 * i / n;
    p.emplace_back(r * std::cos(a), r * std::sin(a), 0.05 * i / n);
  }
  return p;
}

}  // namespace

TEST_CASE("DTW of a path with itself is 0") {
  const Path a = circle(50);
  CHECK(dtwMeanDistance(a, a) == 0.0);
}

TEST_CASE("DTW of a path and its copy shifted by a constant d is d") {
  const Path a = circle(40);
  const Eigen::Vector3d offset(0.003, -0.004, 0.012);  // |offset| = 0.013 m
  Path b = a;
  for (Eigen::Vector3d& p : b) p += offset;
  CHECK(dtwMeanDistance(a, b) == doctest::Approx(0.013).epsilon(1e-12));
  CHECK(dtwMeanDistance(b, a) == doctest::Approx(0.013).epsilon(1e-12));
}

TEST_CASE("DTW of a path and a time-warped copy (samples held for varying times) is 0") {
  const Path a = circle(60);
  Path b;
  for (int i = 0; i < 60; ++i) {
    const int copies = i < 10 ? 3 : i % 5 == 0 ? 2 : 1;  // slow start, hesitations
    for (int k = 0; k < copies; ++k) b.push_back(a[static_cast<std::size_t>(i)]);
  }
  CHECK(b.size() != a.size());
  CHECK(dtwMeanDistance(a, b) == 0.0);
  CHECK(dtwMeanDistance(b, a) == 0.0);
}

TEST_CASE("DTW is the mean per matched pair: one far point among matching ones") {
  // a = (0, 1, 2) on x, b = (0, 1, 5): pairs (0,0) (1,1) (2,5) cost 3 over 3 pairs.
  const Path a = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  const Path b = {{0, 0, 0}, {1, 0, 0}, {5, 0, 0}};
  CHECK(dtwMeanDistance(a, b) == doctest::Approx(1.0));
  // A different path is farther than a warped copy of itself.
  // Concentric circles 2 cm apart: no alignment brings them closer than 2 cm.
  CHECK(dtwMeanDistance(circle(50), circle(70, 0.12)) >= 0.02 - 1e-12);
  CHECK(std::isnan(dtwMeanDistance({}, a)));
}

TEST_CASE("latency statistics are nearest-rank p50/p99 and the maximum") {
  std::vector<double> v;
  for (int i = 100; i >= 1; --i) v.push_back(i);  // 1..100, unsorted
  const nao::rt::LatencyStats s = latencyStats(v);
  CHECK(s.p50 == 50.0);
  CHECK(s.p99 == 99.0);
  CHECK(s.max == 100.0);
  CHECK(latencyStats({}).max == 0.0);
  CHECK(latencyStats({7.0}).p99 == 7.0);
}
