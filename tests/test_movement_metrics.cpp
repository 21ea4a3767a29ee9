// The measures of whether a rollout makes the movement (toolchain movement_metrics.hpp), checked
// on paths whose answers are known in closed form: circles drawn a known number of times at a
// known speed, back-and-forth strokes that draw no loop, copies and shifted copies of a path.
#include "nao/tools/command.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/movement_metrics.hpp"
#include "nao/metrics.hpp"
#include <Eigen/Geometry>

#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <string>

using namespace nao;
using namespace nao::tools;

namespace {

// `loops` turns of a circle of radius r about c in the plane (u, v), n points per turn, plus
// `still` points held at the start before and after (so the middle stretch is the circling).
HandPath circle(const Eigen::Vector3d& c, const Eigen::Vector3d& u, const Eigen::Vector3d& v, double r, double loops,
                int n, int still = 0, double sense = 1.0) {
  HandPath p;
  for (int i = 0; i < still; ++i) p.push_back(c + r * u);
  const int total = static_cast<int>(std::lround(loops * n));
  for (int i = 0; i <= total; ++i) {
    const double a = sense * 2.0 * M_PI * i / n;
    p.push_back(c + r * (std::cos(a) * u + std::sin(a) * v));
  }
  for (int i = 0; i < still; ++i) p.push_back(p.back());
  return p;
}

const Eigen::Vector3d kX = Eigen::Vector3d::UnitX(), kY = Eigen::Vector3d::UnitY(), kZ = Eigen::Vector3d::UnitZ();

}  // namespace

TEST_CASE("the middle stretch is the middle 60 % of the ticks") {
  CHECK(middleStretch(10).begin == 2);
  CHECK(middleStretch(10).end == 8);
  CHECK(middleStretch(11).begin == 2);
  CHECK(middleStretch(11).end == 9);
  CHECK(middleStretch(1).end == 0);
}

TEST_CASE("a circle drawn k times over the middle stretch counts k loops, either sense, in any plane") {
  // 100 ticks: the middle 60 (ticks 20..79) are 59 steps of 1/20 turn each.
  for (const double sense : {1.0, -1.0}) {
    HandPath p;
    for (int i = 0; i < 100; ++i) {
      const double a = sense * 2.0 * M_PI * (i - 20) / 20.0;
      p.push_back(Eigen::Vector3d(0.1, -0.1, 0.2) + 0.05 * (std::cos(a) * kX + std::sin(a) * kZ));
    }
    const Eigen::Matrix<double, 3, 2> plane = loopPlane({p});
    // The plane is x-z: its normal is ±y.
    CHECK(std::abs(plane.col(0).cross(plane.col(1)).dot(kY)) == doctest::Approx(1.0).epsilon(1e-9));
    CHECK(loopCount(p, plane) == doctest::Approx(59.0 / 20.0).epsilon(1e-9));
  }
}

TEST_CASE("a stroke back and forth along an arc draws no loop") {
  // ±60° of a circle, swept there and back with a period of 30 ticks.
  const auto strokes = [](int ticks) {
    HandPath p;
    for (int i = 0; i < ticks; ++i) {
      const double a = M_PI / 3.0 * std::sin(2.0 * M_PI * i / 30.0);
      p.push_back(0.05 * (std::cos(a) * kX + std::sin(a) * kZ));
    }
    return p;
  };
  const Eigen::Matrix<double, 3, 2> plane = loopPlane({circle(Eigen::Vector3d::Zero(), kX, kZ, 0.05, 3, 20, 15)});
  // 151 ticks: the middle stretch (ticks 30..120) is 3 whole strokes and ends where it began.
  CHECK(loopCount(strokes(151), plane) < 1e-9);
  // Ending mid-stroke counts at most the half turn the arc spans about its own centroid, whatever
  // the number of strokes: never a loop.
  for (const int ticks : {120, 300, 600}) {
    CAPTURE(ticks);
    CHECK(loopCount(strokes(ticks), plane) < 0.6);
  }
}

TEST_CASE("the middle RMS speed of a circle is its chord per tick over the period") {
  const double r = 0.08, period = 0.1;
  const int n = 25;
  const HandPath p = circle(Eigen::Vector3d(0.0, 0.0, 0.3), kY, kZ, r, 5, n);
  const double chord = 2.0 * r * std::sin(M_PI / n);
  CHECK(middleRmsSpeed(p, period) == doctest::Approx(chord / period).epsilon(1e-12));
  // Holding still in the middle: zero.
  CHECK(middleRmsSpeed(HandPath(50, Eigen::Vector3d(0.1, 0.2, 0.3)), period) == 0.0);
  CHECK(std::isnan(middleRmsSpeed(HandPath(1, Eigen::Vector3d::Zero()), period)));  // no step
}

TEST_CASE("runs are distinct unless a near-copy of another run is closer than 1 mm") {
  const HandPath a = circle(Eigen::Vector3d::Zero(), kX, kZ, 0.05, 2, 20);
  HandPath shifted = a, near = a;
  for (auto& x : shifted) x += Eigen::Vector3d(0.0, 0.005, 0.0);  // 5 mm away
  for (auto& x : near) x += Eigen::Vector3d(0.0, 0.0004, 0.0);    // 0.4 mm away
  CHECK(distinctRuns({a, shifted}) == 2);
  CHECK(distinctRuns({a, shifted, near}) == 1);  // a and its near-copy both fall out
  CHECK(distinctRuns({a, a, a}) == 0);
  CHECK(distinctRuns({a}) == 1);
}

TEST_CASE("the medoid is the path with the smallest summed DTW to the others") {
  std::vector<HandPath> paths;
  for (const double dy : {0.0, 0.01, 0.02, 0.035, 0.1}) {
    HandPath p = circle(Eigen::Vector3d::Zero(), kX, kZ, 0.05, 1, 20);
    for (auto& x : p) x.y() += dy;
    paths.push_back(p);
  }
  CHECK(medoid(paths, {0, 1, 2, 3, 4}) == 2);
  CHECK(medoid(paths, {0, 1}) == 0);  // a tie goes to the earlier member
  CHECK(medoid(paths, {4, 3, 0}) == 3);
  CHECK_THROWS_AS(medoid(paths, {}), UserError);
}

TEST_CASE("nearest starts come nearest first, ties to the lower index") {
  std::vector<JointVector> starts;
  for (const double x : {0.3, 0.1, 0.2, 0.1, 0.5}) starts.push_back(JointVector::Constant(x));
  const std::vector<int> n = nearestStarts(starts, JointVector::Constant(0.12), 3);
  REQUIRE(n.size() == 3);
  CHECK(n[0] == 1);
  CHECK(n[1] == 3);
  CHECK(n[2] == 2);
  CHECK(nearestStarts(starts, JointVector::Zero(), 10).size() == 5);
}

TEST_CASE("a run's code is the medoid replay's demonstration: the runtime's choice against nearestStarts + medoid") {
  // 30 demonstrations with random starts (some equal, for ties) and circles of random centres;
  // the runtime chooses from the table of their DTWs, the evaluator from the paths themselves.
  std::mt19937_64 rng(5);
  const auto u = [&](double lo, double hi) { return lo + (hi - lo) * (static_cast<double>(rng() >> 11) * 0x1.0p-53); };
  ModelRunCodes codes;
  codes.d = 1;
  std::vector<HandPath> paths;
  for (int i = 0; i < 30; ++i) {
    codes.names.push_back("d" + std::to_string(i));
    codes.q.push_back(i % 7 == 3 ? codes.q[static_cast<std::size_t>(i - 1)] : JointVector(JointVector::Zero()));
    if (i % 7 != 3)
      for (int k = 0; k < kNumJoints; ++k) codes.q.back()[k] = u(-1.0, 1.0);
    codes.code.push_back(static_cast<float>(i));
    paths.push_back(circle(Eigen::Vector3d(u(-0.05, 0.05), u(-0.05, 0.05), 0.0), kX, kY, u(0.03, 0.06), u(0.5, 2.0), 24));
  }
  const std::size_t n = paths.size();
  codes.dtw_m.assign(n * n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t k = i + 1; k < n; ++k) codes.dtw_m[i * n + k] = codes.dtw_m[k * n + i] = rt::dtwMeanDistance(paths[i], paths[k]);
  int differs_from_nearest = 0;
  for (int trial = 0; trial < 200; ++trial) {
    JointVector q0;
    for (int k = 0; k < kNumJoints; ++k) q0[k] = u(-1.2, 1.2);
    if (trial % 10 == 0) q0 = codes.q[static_cast<std::size_t>(trial % 30)];  // on a start, and on the tied pairs
    const std::vector<int> near = nearestStarts(codes.q, q0, kRunCodeNearest);
    const int expected = medoid(paths, near);
    CHECK(runCodeIndex(codes, q0) == expected);
    differs_from_nearest += expected != near.front() ? 1 : 0;
    // With one demonstration left out: the choice among the others (its start's index removed).
    const int out = trial % 30;
    std::vector<JointVector> others = codes.q;
    others.erase(others.begin() + out);
    std::vector<int> near_others = nearestStarts(others, q0, kRunCodeNearest);
    for (int& i : near_others) i += i >= out ? 1 : 0;
    CHECK(runCodeIndex(codes, q0, out) == medoid(paths, near_others));
  }
  CHECK(differs_from_nearest > 50);  // the medoid is not merely the nearest start
  CHECK(runCodeIndex(ModelRunCodes{}, JointVector::Zero()) == -1);
  ModelRunCodes one = codes;  // its only demonstration left out: nothing to choose
  one.names.resize(1);
  one.q.resize(1);
  one.dtw_m = {0.0};
  CHECK(runCodeIndex(one, JointVector::Zero(), 0) == -1);
  CHECK(runCodeIndex(one, JointVector::Zero()) == 0);
  ModelRunCodes three = codes;  // fewer demonstrations than kRunCodeNearest: the medoid of all
  three.names.resize(3);
  three.q.resize(3);
  three.dtw_m = {0.0, codes.dtw_m[1], codes.dtw_m[2], codes.dtw_m[n], 0.0, codes.dtw_m[n + 2], codes.dtw_m[2 * n], codes.dtw_m[2 * n + 1], 0.0};
  CHECK(runCodeIndex(three, JointVector::Zero()) == medoid(paths, nearestStarts(three.q, JointVector::Zero(), 5)));
}

TEST_CASE("the RMS of a sequence of joint vectors runs over every tick and joint") {
  CHECK(rmsOf({}) == 0.0);
  CHECK(rmsOf({JointVector::Constant(2.0), JointVector::Constant(-2.0)}) == doctest::Approx(2.0));
  JointVector one = JointVector::Zero();
  one[0] = 1.0;
  CHECK(rmsOf({one}) == doctest::Approx(std::sqrt(1.0 / 5.0)));
}

TEST_CASE("points that span no plane are refused for the loop plane") {
  HandPath line;
  for (int i = 0; i < 30; ++i) line.push_back(Eigen::Vector3d(0.01 * i, 0.0, 0.0));
  CHECK_THROWS_AS(loopPlane({line}), UserError);
  CHECK_THROWS_AS(loopPlane({}), UserError);
}
