// The policy's training data (docs/policy.md "Data"): samples checked by hand, the split is by
// demonstration, statistics come from the training split only, baselines match an independent
// computation, the split and the fingerprint are deterministic, bad files are named.
#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/sim_arm.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <set>

using namespace nao;
using namespace nao::tools;

namespace {

JointVector jv(double a, double b, double c, double d, double e) {
  JointVector v;
  v << a, b, c, d, e;
  return v;
}

PolicyDemo demo(const std::string& name, const std::vector<JointVector>& f, const std::vector<int>& label) {
  PolicyDemo d;
  d.name = name;
  d.f = f;
  d.label = label;
  for (std::size_t t = 0; t < f.size(); ++t) d.t_s.push_back(0.1 * static_cast<double>(t));
  return d;
}

// A smooth deterministic trajectory per (movement, index): n samples.
std::vector<JointVector> wave(int movement, int index, int n) {
  std::vector<JointVector> f;
  for (int t = 0; t < n; ++t) {
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j)
      q[j] = 0.3 * std::sin(0.05 * (t + 1) * (j + 1) + 0.7 * index + 1.3 * movement) + 0.1 * j;
    f.push_back(q);
  }
  return f;
}

// n_per demonstrations of each of the three standard movements, K = 2 centroids each.
PolicyData standardSet(int n_per) {
  std::map<std::string, std::vector<JointVector>> centroids;
  std::vector<PolicyDemo> demos;
  const char* names[] = {"whole_arm", "elbow", "wrist"};
  for (int m = 0; m < 3; ++m) {
    centroids[names[m]] = {JointVector::Constant(0.1 * m), JointVector::Constant(-0.1 * m)};
    for (int i = 0; i < n_per; ++i) {
      char name[64];
      std::snprintf(name, sizeof name, "%s_%03d", names[m], i);
      const std::vector<JointVector> f = wave(m, i, 20 + 3 * i);
      std::vector<int> label;
      for (std::size_t t = 0; t < f.size(); ++t) label.push_back(static_cast<int>((t / 4) % 2));
      demos.push_back(demo(name, f, label));
    }
  }
  return makePolicyData(centroids, demos);
}

std::vector<int> allDemos(const PolicyData& data) {
  std::vector<int> all(data.demos.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  return all;
}

void writeText(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

std::string centroidsJson() {
  return R"({"k": 2, "movements": {
    "wrist": {"centroids": [[0,0,0,0,0],[1,1,1,1,1]]},
    "elbow": {"centroids": [[0.5,0.5,0.5,0.5,0.5],[-1,-1,-1,-1,-1]]}}})";
}

std::string loadError(const std::string& dir) {
  try {
    loadPolicyData(dir);
  } catch (const UserError& e) {
    return e.what();
  }
  FAIL("loading " << dir << " should have thrown UserError");
  return {};
}

}  // namespace

TEST_CASE("samples of a tiny two-demo set are q(t), a(t-1), r(t), m, s and a(t) as worked out by hand") {
  const JointVector c0 = jv(0, 0, 0, 0, 0), c1 = jv(1, 2, 3, 4, 5);
  const JointVector f0 = jv(0.1, 0.2, 0.3, 0.4, 0.5), f1 = jv(0.2, 0.2, 0.1, 0.4, 0.9), f2 = jv(0.0, 0.5, 0.1, 0.3, 0.9);
  // "b_000" sorts after "a_000": the first movement (by name) is "a" -> index 0.
  const PolicyData data =
      makePolicyData({{"b", {c0, c1}}, {"a", {c1, c0}}}, {demo("b_000", {f0, f1, f2}, {0, 1, 1}), demo("a_000", {f2, f0}, {1, 0})});
  REQUIRE(data.movement_names == std::vector<std::string>{"a", "b"});
  REQUIRE(data.demos.size() == 2);
  CHECK(data.demos[0].name == "a_000");
  CHECK(data.demos[0].movement == 0);
  CHECK(data.demos[1].movement == 1);
  CHECK(data.demos[1].measured == std::vector<std::uint8_t>{1, 1, 1});  // missing column = all measured

  const std::vector<PolicySample> a = buildSamples(data, 0, 256);
  REQUIRE(a.size() == 1);  // 2 samples, 1 with a successor
  CHECK(a[0].q == f2);
  CHECK(a[0].a_prev == JointVector::Zero());
  CHECK(a[0].r == c0);  // label 1 of movement "a" = c0
  CHECK(a[0].a == f0 - f2);
  CHECK(a[0].movement == 0);
  CHECK(a[0].step == 0);

  const std::vector<PolicySample> b = buildSamples(data, 1, 256);
  REQUIRE(b.size() == 2);
  CHECK(b[0].q == f0);
  CHECK(b[0].a_prev == JointVector::Zero());
  CHECK(b[0].r == c0);
  CHECK(b[0].a == f1 - f0);
  CHECK(b[1].q == f1);
  CHECK(b[1].a_prev == f1 - f0);
  CHECK(b[1].r == c1);
  CHECK(b[1].a == f2 - f1);
  CHECK(b[1].movement == 1);
  CHECK(b[1].step == 1);
  CHECK(b[1].demo == 1);

  // Steps clamp at max_steps - 1.
  CHECK(buildSamples(data, 1, 1)[1].step == 0);
}

TEST_CASE("the standard movements get indices elbow = 0, whole_arm = 1, wrist = 2") {
  const PolicyData data = standardSet(1);
  CHECK(data.movement_names == std::vector<std::string>{"elbow", "whole_arm", "wrist"});
  for (const PolicyDemo& d : data.demos)
    CHECK(data.movement_names[static_cast<std::size_t>(d.movement)] + "_000" == d.name);
}

TEST_CASE("canonical pace: a trajectory resampled linearly into the pace's ticks, then held, its length unchanged") {
  // A ramp f(t) = f0 + t·v: linear interpolation of it is exact, so the paced ramp is
  // f0 + t·(n−1)/(l−1)·v for t < l, whatever the rounding of the sample index.
  const JointVector f0 = jv(0.1, -0.2, 0.3, 0.4, -0.5), v = jv(0.01, 0.02, -0.03, 0.005, 0.0);
  const int n = 37;
  std::vector<JointVector> ramp;
  for (int t = 0; t < n; ++t) ramp.push_back(f0 + static_cast<double>(t) * v);
  for (const int l : {2, 3, 10, 19, 36}) {
    CAPTURE(l);
    const std::vector<JointVector> p = pacedTrajectory(ramp, l);
    REQUIRE(p.size() == ramp.size());
    CHECK(p.front() == ramp.front());
    for (int t = 0; t < n; ++t) {
      const double u = t < l ? static_cast<double>(t) * (n - 1) / (l - 1) : n - 1.0;
      CHECK((p[static_cast<std::size_t>(t)] - (f0 + u * v)).cwiseAbs().maxCoeff() < 1e-12);
    }
    // The movement is over at sample l − 1 and held from there.
    CHECK(p[static_cast<std::size_t>(l - 1)] == ramp.back());
  }
  // A pace at least the length leaves the trajectory as it is; a curve keeps its samples'
  // values where the resampling lands on one (t·(n−1) a multiple of l − 1).
  const std::vector<JointVector> w = wave(1, 2, 41);
  CHECK(pacedTrajectory(w, 41) == w);
  CHECK(pacedTrajectory(w, 500) == w);
  const std::vector<JointVector> half = pacedTrajectory(w, 21);  // u = 2t
  for (int t = 0; t < 21; ++t) CHECK(half[static_cast<std::size_t>(t)] == w[static_cast<std::size_t>(2 * t)]);
  for (int t = 21; t < 41; ++t) CHECK(half[static_cast<std::size_t>(t)] == w.back());
  CHECK_THROWS_AS(pacedTrajectory(w, 1), UserError);
}

TEST_CASE("DTW pace: a time-warped copy is warped back onto its template, loops lined up") {
  // The template: two loops of a circle in joints 1 and 2 over 60 samples. The demonstration: the
  // same path on a clock that runs slow, then fast (clock(x) = template time of demonstration time
  // x), 80 samples: the warp's slope is 1.91 then 1.03, inside the bounds [1/2, 2].
  const int l = 60, n = 80;
  const auto pose = [](double s) {  // s in [0, 1]: two loops
    return jv(0.2 + 0.3 * s, 0.4 * std::sin(4.0 * M_PI * s), 0.4 * std::cos(4.0 * M_PI * s), -0.1, 0.05 * s);
  };
  std::vector<JointVector> tmpl, f;
  for (int k = 0; k < l; ++k) tmpl.push_back(pose(static_cast<double>(k) / (l - 1)));
  const auto clock = [](double x) { return x < 0.5 ? 0.7 * x : 0.35 + 1.3 * (x - 0.5); };  // [0,1] -> [0,1]
  for (int t = 0; t < n; ++t) f.push_back(pose(clock(static_cast<double>(t) / (n - 1))));

  const std::optional<std::vector<double>> warp = dtwWarp(f, tmpl);
  REQUIRE(warp);
  const std::vector<double>& u = *warp;
  REQUIRE(u.size() == static_cast<std::size_t>(l));
  CHECK(u.front() == 0.0);
  CHECK(u.back() == n - 1.0);
  CHECK(std::is_sorted(u.begin(), u.end()));
  // The warp inverts the clock: template sample k sits at f's sample clock^-1(k/(l−1))·(n−1),
  // within the grids' resolution (a few samples).
  const auto inverse = [](double y) { return y < 0.35 ? y / 0.7 : 0.5 + (y - 0.35) / 1.3; };
  double worst_u = 0.0;
  for (int k = 0; k < l; ++k)
    worst_u = std::max(worst_u, std::abs(u[static_cast<std::size_t>(k)] - inverse(static_cast<double>(k) / (l - 1)) * (n - 1)));
  CHECK(worst_u < 3.0);

  // Paced by DTW, the demonstration lies on the template sample by sample (the loops line up);
  // paced linearly it does not (its clock is not linear).
  const std::vector<JointVector> dtw = pacedTrajectory(f, tmpl, PaceMethod::kDtw);
  const std::vector<JointVector> lin = pacedTrajectory(f, tmpl, PaceMethod::kLinear);
  REQUIRE(dtw.size() == f.size());
  CHECK(lin == pacedTrajectory(f, l));
  double worst_dtw = 0.0, worst_lin = 0.0;
  for (int k = 0; k < l; ++k) {
    worst_dtw = std::max(worst_dtw, (dtw[static_cast<std::size_t>(k)] - tmpl[static_cast<std::size_t>(k)]).norm());
    worst_lin = std::max(worst_lin, (lin[static_cast<std::size_t>(k)] - tmpl[static_cast<std::size_t>(k)]).norm());
  }
  CHECK(worst_dtw < 0.1);
  CHECK(worst_lin > 0.4);
  CHECK(dtw.front() == f.front());
  for (int t = l - 1; t < n; ++t) CHECK(dtw[static_cast<std::size_t>(t)] == f.back());
  // A demonstration no longer than its template is left as it is; a trajectory onto itself is itself.
  CHECK(pacedTrajectory(tmpl, f, PaceMethod::kDtw) == tmpl);
  CHECK(pacedTrajectory(tmpl, tmpl, PaceMethod::kDtw) == tmpl);
  const std::optional<std::vector<double>> self = dtwWarp(tmpl, tmpl);
  REQUIRE(self);
  for (int k = 0; k < l; ++k) CHECK((*self)[static_cast<std::size_t>(k)] == doctest::Approx(k).epsilon(1e-12));
  // The slope bound: every step of the warp within [1/2, 2]; a demonstration more than twice as
  // long as its template has no warp, and is paced linearly instead.
  for (int k = 1; k < l; ++k) {
    CHECK(u[static_cast<std::size_t>(k)] - u[static_cast<std::size_t>(k - 1)] <= 2.0 + 1e-12);
    CHECK(u[static_cast<std::size_t>(k)] - u[static_cast<std::size_t>(k - 1)] >= 0.5 - 1e-12);
  }
  std::vector<JointVector> slow;
  for (int t = 0; t < 2 * l; ++t) slow.push_back(pose(static_cast<double>(t) / (2 * l - 1)));
  CHECK_FALSE(dtwWarp(slow, tmpl));
  CHECK(dtwWarp(std::vector<JointVector>(slow.begin(), slow.begin() + 2 * l - 1), tmpl));  // 2 (L − 1) + 1 samples
  CHECK(pacedTrajectory(slow, tmpl, PaceMethod::kDtw) == pacedTrajectory(slow, l));
  CHECK_THROWS_AS(dtwWarp({f.front()}, tmpl), UserError);
  CHECK(parsePaceMethod("dtw") == PaceMethod::kDtw);
  CHECK(std::string(paceMethodName(PaceMethod::kLinear)) == "linear");
  CHECK_THROWS_AS(parsePaceMethod("fast"), UserError);
}

TEST_CASE("canonical pace of a data set: each movement onto its template, names, times and lengths unchanged") {
  const PolicyData data = standardSet(3);  // lengths 20, 23, 26 per movement
  const std::vector<int> all = allDemos(data);
  // The shortest listed demonstration of each movement (index 0 of each, 20 samples).
  const std::vector<int> tmpl = paceTemplates(data, all);
  REQUIRE(tmpl.size() == 3);
  for (int m = 0; m < 3; ++m) {
    CHECK(data.demos[static_cast<std::size_t>(tmpl[static_cast<std::size_t>(m)])].movement == m);
    CHECK(data.demos[static_cast<std::size_t>(tmpl[static_cast<std::size_t>(m)])].f.size() == 20);
  }
  // Only the listed demonstrations count: without the index-0 demos, the 23-sample ones.
  std::vector<int> later;
  for (int d : all)
    if (data.demos[static_cast<std::size_t>(d)].name.back() != '0') later.push_back(d);
  for (int t : paceTemplates(data, later)) CHECK(data.demos[static_cast<std::size_t>(t)].f.size() == 23);
  CHECK(paceTemplates(data, {}) == std::vector<int>{-1, -1, -1});

  for (const PaceMethod method : {PaceMethod::kLinear, PaceMethod::kDtw}) {
    CAPTURE(paceMethodName(method));
    const PolicyData p = pacedData(data, tmpl, method);
    REQUIRE(p.demos.size() == data.demos.size());
    CHECK(p.movement_names == data.movement_names);
    for (std::size_t i = 0; i < p.demos.size(); ++i) {
      const PolicyDemo &a = data.demos[i], &b = p.demos[i];
      CAPTURE(a.name);
      CHECK(b.name == a.name);
      CHECK(b.t_s == a.t_s);
      const std::vector<JointVector>& t = data.demos[static_cast<std::size_t>(tmpl[static_cast<std::size_t>(a.movement)])].f;
      CHECK(b.f == pacedTrajectory(a.f, t, method));
      REQUIRE(b.label.size() == a.label.size());
      // The held tail carries the last sample's label.
      for (std::size_t k = std::min(a.f.size(), t.size()); k < b.label.size(); ++k) CHECK(b.label[k] == a.label.back());
    }
    // The result is a valid data set, and pacing changes its fingerprint.
    CHECK_NOTHROW(makePolicyData({{"elbow", data.centroids[0]}, {"whole_arm", data.centroids[1]}, {"wrist", data.centroids[2]}}, p.demos));
    CHECK(dataFingerprint(p) != dataFingerprint(data));
  }
  CHECK_THROWS_AS(pacedData(data, {tmpl[0], tmpl[1]}, PaceMethod::kLinear), UserError);
  CHECK_THROWS_AS(pacedData(data, {tmpl[0], tmpl[0], tmpl[2]}, PaceMethod::kLinear), UserError);  // wrong movement
  CHECK_THROWS_AS(pacedData(data, {tmpl[0], -1, tmpl[2]}, PaceMethod::kDtw), UserError);
}

TEST_CASE("the split is by demonstration: every demo in exactly one part, round(0.2 n) validation per movement") {
  const PolicyData data = standardSet(10);
  const PolicySplit split = splitByDemonstration(data, 0.2, 7);
  std::set<int> train(split.train.begin(), split.train.end()), val(split.val.begin(), split.val.end());
  CHECK(train.size() + val.size() == data.demos.size());
  for (int d : val) CHECK_MESSAGE(train.count(d) == 0, data.demos[static_cast<std::size_t>(d)].name << " in both");
  for (int m = 0; m < 3; ++m) {
    int n_val = 0;
    for (int d : val) n_val += data.demos[static_cast<std::size_t>(d)].movement == m;
    CHECK(n_val == 2);
  }
  // No frame of a validation demo is among the training samples.
  for (const PolicySample& s : buildSamples(data, split.train, 256)) CHECK(val.count(s.demo) == 0);

  // Small movements: 2 demos -> 1 validation; 1 demo -> training only.
  const PolicySplit two = splitByDemonstration(standardSet(2), 0.2, 7);
  CHECK(two.val.size() == 3);
  CHECK(two.train.size() == 3);
  const PolicySplit one = splitByDemonstration(standardSet(1), 0.2, 7);
  CHECK(one.val.empty());
  CHECK(one.train.size() == 3);
  CHECK_THROWS_AS(splitByDemonstration(data, 1.0, 7), UserError);
}

TEST_CASE("the split is a function of the seed: equal seeds give equal splits, the seed changes it") {
  const PolicyData data = standardSet(10);
  const PolicySplit a = splitByDemonstration(data, 0.2, 42), b = splitByDemonstration(data, 0.2, 42);
  CHECK(a.train == b.train);
  CHECK(a.val == b.val);
  int differing = 0;
  for (std::uint64_t seed = 1; seed <= 5; ++seed) differing += splitByDemonstration(data, 0.2, seed).val != a.val;
  CHECK_MESSAGE(differing >= 4, differing << " of 5 other seeds gave a different split");
}

TEST_CASE("normalisation statistics come from the training split only and match a hand computation") {
  PolicyData data = standardSet(5);
  const PolicySplit split = splitByDemonstration(data, 0.2, 3);
  REQUIRE(!split.val.empty());
  const NormStats before = normStats(buildSamples(data, split.train, 256));

  // Independent computation straight from f: mean and population std of f(t), t < n-1.
  for (int j = 0; j < kNumJoints; ++j) {
    double sum = 0.0, sum_a = 0.0, count = 0.0;
    for (int d : split.train) {
      const auto& f = data.demos[static_cast<std::size_t>(d)].f;
      for (std::size_t t = 0; t + 1 < f.size(); ++t) {
        sum += f[t][j];
        sum_a += f[t + 1][j] - f[t][j];
        count += 1;
      }
    }
    const double mean = sum / count, mean_a = sum_a / count;
    double var = 0.0, var_a = 0.0;
    for (int d : split.train) {
      const auto& f = data.demos[static_cast<std::size_t>(d)].f;
      for (std::size_t t = 0; t + 1 < f.size(); ++t) {
        var += (f[t][j] - mean) * (f[t][j] - mean);
        var_a += (f[t + 1][j] - f[t][j] - mean_a) * (f[t + 1][j] - f[t][j] - mean_a);
      }
    }
    CHECK(before.q_mean[j] == doctest::Approx(mean).epsilon(1e-12));
    CHECK(before.q_std[j] == doctest::Approx(std::sqrt(var / count)).epsilon(1e-12));
    CHECK(before.a_mean[j] == doctest::Approx(mean_a).epsilon(1e-12));
    CHECK(before.a_std[j] == doctest::Approx(std::sqrt(var_a / count)).epsilon(1e-12));
  }

  // Wildly different validation demos leave the statistics bit-for-bit unchanged.
  for (int d : split.val)
    for (JointVector& q : data.demos[static_cast<std::size_t>(d)].f) q *= 100.0;
  const NormStats after = normStats(buildSamples(data, splitByDemonstration(data, 0.2, 3).train, 256));
  CHECK(after.q_mean == before.q_mean);
  CHECK(after.q_std == before.q_std);
  CHECK(after.a_mean == before.a_mean);
  CHECK(after.a_std == before.a_std);
  CHECK(after.r_mean == before.r_mean);
  CHECK(after.r_std == before.r_std);
}

TEST_CASE("a constant joint gets the floored standard deviation, never 0") {
  const PolicyData data = makePolicyData({{"m", {JointVector::Zero()}}},
                                         {demo("m_0", {JointVector::Ones(), JointVector::Ones(), JointVector::Ones()}, {0, 0, 0})});
  const NormStats st = normStats(buildSamples(data, 0, 256));
  CHECK(st.q_std == JointVector::Constant(kMinStd));
  CHECK(st.a_std == JointVector::Constant(kMinStd));
  CHECK(st.r_std == JointVector::Constant(kMinStd));
}

TEST_CASE("baselines equal an independent hand computation from the trajectories") {
  const PolicyData data = standardSet(3);
  double zero = 0.0, repeat = 0.0, count = 0.0;
  for (const PolicyDemo& d : data.demos)
    for (std::size_t t = 0; t + 1 < d.f.size(); ++t)
      for (int j = 0; j < kNumJoints; ++j) {
        const double a = d.f[t + 1][j] - d.f[t][j];
        const double a_prev = t == 0 ? 0.0 : d.f[t][j] - d.f[t - 1][j];
        zero += a * a;
        repeat += (a - a_prev) * (a - a_prev);
        count += 1;
      }
  const Baselines b = baselines(buildSamples(data, allDemos(data), 256));
  CHECK(b.zero_action == doctest::Approx(zero / count).epsilon(1e-12));
  CHECK(b.repeat_last == doctest::Approx(repeat / count).epsilon(1e-12));
  // Smooth trajectories: repeating the last action beats predicting none.
  CHECK(b.repeat_last < b.zero_action);
}

TEST_CASE("the data fingerprint is deterministic and changes with any value") {
  const PolicyData a = standardSet(2);
  PolicyData b = standardSet(2);
  CHECK(dataFingerprint(a) == dataFingerprint(b));
  b.demos[3].f[5][2] += 1e-12;
  CHECK(dataFingerprint(a) != dataFingerprint(b));
  PolicyData c = standardSet(2);
  c.demos[0].measured[1] = 0;
  CHECK(dataFingerprint(a) != dataFingerprint(c));
  CHECK(hex64(0x0123456789abcdefull) == "0123456789abcdef");
  CHECK(hex64(dataFingerprint(a)).size() == 16);
}

TEST_CASE("a data directory reads with and without the measured column") {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests" / "policy_data_ok";
  std::filesystem::remove_all(dir);
  writeText(dir / "centroids.json", centroidsJson());
  writeText(dir / "wrist_000" / "features.csv",
            "t_s,label,measured,f_0,f_1,f_2,f_3,f_4\n0,0,1,0,0,0,0,0\n0.1,1,0,0.1,0.2,0.3,0.4,0.5\n0.2,1,1,0.2,0.2,0.2,0.2,0.2\n");
  writeText(dir / "elbow_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0.1,1,1,1,1,1,1\n0.2,0,2,2,2,2,2\n");
  writeText(dir / "notes" / "readme.txt", "not a demonstration");
  const PolicyData data = loadPolicyData(dir.string());
  REQUIRE(data.movement_names == std::vector<std::string>{"elbow", "wrist"});
  REQUIRE(data.clusters() == 2);
  CHECK(data.centroids[0][0] == JointVector::Constant(0.5));
  REQUIRE(data.demos.size() == 2);
  CHECK(data.demos[0].name == "elbow_000");
  CHECK(data.demos[0].measured == std::vector<std::uint8_t>{1, 1});
  CHECK(data.demos[1].measured == std::vector<std::uint8_t>{1, 0, 1});
  CHECK(data.demos[1].label == std::vector<int>{0, 1, 1});
  CHECK(data.demos[1].f[1] == jv(0.1, 0.2, 0.3, 0.4, 0.5));
  CHECK(buildSamples(data, 1, 256)[1].r == JointVector::Ones());
}

TEST_CASE("a broken data directory is rejected with the file and line") {
  const auto root = std::filesystem::temp_directory_path() / "nao_rt_tests" / "policy_data_bad";
  std::filesystem::remove_all(root);
  CHECK(loadError((root / "nope").string()).find("not a directory") != std::string::npos);

  const auto no_json = root / "no_json";
  writeText(no_json / "elbow_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,0,0,0,0,0,0\n");
  CHECK(loadError(no_json.string()).find("centroids.json") != std::string::npos);

  const auto bad_json = root / "bad_json";
  writeText(bad_json / "centroids.json", R"({"movements": {"elbow": {"centroids": [[1,2,3]]}}})");
  CHECK(loadError(bad_json.string()).find("movements/elbow/centroids/0") != std::string::npos);

  const auto no_demos = root / "no_demos";
  writeText(no_demos / "centroids.json", centroidsJson());
  CHECK(loadError(no_demos.string()).find("features.csv") != std::string::npos);

  const auto bad_value = root / "bad_value";
  writeText(bad_value / "centroids.json", centroidsJson());
  writeText(bad_value / "elbow_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,0,0,0,0,0,0\n0.1,0,0,x,0,0,0\n");
  const std::string e1 = loadError(bad_value.string());
  CHECK_MESSAGE(e1.find("elbow_000/features.csv:3") != std::string::npos, e1);

  const auto bad_label = root / "bad_label";
  writeText(bad_label / "centroids.json", centroidsJson());
  writeText(bad_label / "wrist_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,0,0,0,0,0,0\n0.1,2,0,0,0,0,0\n");
  const std::string e2 = loadError(bad_label.string());
  CHECK_MESSAGE(e2.find("wrist_000/features.csv:3: label") != std::string::npos, e2);

  const auto bad_movement = root / "bad_movement";
  writeText(bad_movement / "centroids.json", centroidsJson());
  writeText(bad_movement / "knee_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0\n");
  CHECK(loadError(bad_movement.string()).find("'knee' has no centroids") != std::string::npos);

  const auto missing_column = root / "missing_column";
  writeText(missing_column / "centroids.json", centroidsJson());
  writeText(missing_column / "wrist_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3\n0,0,0,0,0,0\n");
  CHECK(loadError(missing_column.string()).find("missing column 'f_4'") != std::string::npos);

  const auto one_sample = root / "one_sample";
  writeText(one_sample / "centroids.json", centroidsJson());
  writeText(one_sample / "wrist_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,0,0,0,0,0,0\n");
  CHECK(loadError(one_sample.string()).find("at least 2") != std::string::npos);
}

namespace {

// A data set whose trajectories are real feature-extracted trajectories of random key poses.
PolicyData blendedSet(const KeyPoseBlend& blend) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::map<std::string, std::vector<JointVector>> centroids;
  std::vector<PolicyDemo> demos;
  for (const char* m : {"elbow", "whole_arm", "wrist"}) {
    std::vector<JointVector> c(4);
    for (JointVector& x : c) x = JointVector::NullaryExpr([&] { return u(rng); });
    centroids[m] = c;
    for (int i = 0; i < 3; ++i) {
      std::vector<double> t;
      std::vector<JointVector> q;
      for (int k = 0; k < 60; ++k) {
        t.push_back(0.1 * k);
        q.push_back(c[static_cast<std::size_t>((k / (5 + i)) % 4)]);
      }
      PolicyDemo d = demo(std::string(m) + "_00" + std::to_string(i), featureTrajectory(c, t, q, blend),
                          keyPoseLabels(c, t, q, t));
      demos.push_back(d);
    }
  }
  return makePolicyData(centroids, demos);
}

}  // namespace

TEST_CASE("demonstrated actions are the expert's: the blend applied to (q, a(t-1), r) of each sample") {
  // Cross-check of two independent paths: differences of the feature-extracted trajectory
  // (buildSamples) and the blend law evaluated on the sample's inputs.
  KeyPoseBlend blend;
  blend.pole = 0.6;
  const PolicyData data = blendedSet(blend);
  const std::vector<PolicySample> samples = buildSamples(data, allDemos(data), 256);
  REQUIRE(samples.size() > 500);
  double worst = 0.0, largest = 0.0;
  for (const PolicySample& s : samples) {
    worst = std::max(worst, (s.a - blend.velocity(s.a_prev, s.q, s.r)).cwiseAbs().maxCoeff());
    largest = std::max(largest, s.a.cwiseAbs().maxCoeff());
  }
  CHECK(worst < 1e-12);
  CHECK(largest > 0.05);  // the trajectories do move
  // Another pole is another expert: the same samples are then not its actions.
  KeyPoseBlend other;
  other.pole = 0.8;
  double off = 0.0;
  for (const PolicySample& s : samples) off = std::max(off, (s.a - other.velocity(s.a_prev, s.q, s.r)).cwiseAbs().maxCoeff());
  CHECK(off > 1e-3);
}

namespace {

// Replays a rollout on a fresh simulated arm with the commands it applied (q(t) + a(t−1) of the
// next tick) and, at every tick, tries the label from a snapshot of the replayed state: returns
// the largest |q(t+1) − f(t+1)| the labels leave over the ticks whose clamped target is within
// one tick's reach, and the largest difference between the replayed and the recorded q.
struct Replay {
  double worst_label_miss = 0.0, worst_q_diff = 0.0, worst_off_trajectory = 0.0;
  std::size_t ticks_checked = 0, ticks_on_target = 0;  ///< label ends within 1e-5 rad of f(t+1)
};

// `target_of(t)`, if given, is where tick t's label should end instead of f(t+1) (aligned labels).
Replay replay(const PolicyData& data, const PolicySequence& s, const SimModel& model,
              const std::function<JointVector(std::size_t)>& target_of = {}) {
  const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
  const ArmModel& arm = model.arm;
  SimData sim(model, d.f.front());
  SimSnapshot snap;
  Replay r;
  for (std::size_t t = 0; t < s.ticks(); ++t) {
    r.worst_q_diff = std::max(r.worst_q_diff, (sim.q - s.q[t]).cwiseAbs().maxCoeff());
    const JointVector target = target_of ? target_of(t) : JointVector(clampToLimits(arm, d.f[t + 1]));
    r.worst_off_trajectory = std::max(r.worst_off_trajectory, (sim.q - clampToLimits(arm, d.f[t])).cwiseAbs().maxCoeff());
    captureSim(sim, snap);
    const JointVector end = stepSim(model, sim, sim.q + s.a[t]);
    const double miss = (end - target).cwiseAbs().maxCoeff();
    r.worst_label_miss = std::max(r.worst_label_miss, miss);
    ++r.ticks_checked;
    if (miss < 1e-5) ++r.ticks_on_target;
    restoreSim(sim, snap);
    const JointVector applied = t + 1 < s.ticks() ? JointVector(s.q[t] + s.a_prev[t + 1]) : JointVector(sim.q + s.a[t]);
    stepSim(model, sim, applied);
  }
  return r;
}

}  // namespace

// Demonstrations an arm can follow: key poses in the middle of the joint ranges, blended with
// pole 0.8, segments of 8-10 ticks.
PolicyData reachableSet(const ArmModel& arm, const KeyPoseBlend& blend) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.3, 0.7);
  std::map<std::string, std::vector<JointVector>> centroids;
  std::vector<PolicyDemo> demos;
  for (const char* m : {"elbow", "whole_arm", "wrist"}) {
    std::vector<JointVector> c(4);
    for (JointVector& x : c)
      for (int j = 0; j < kNumJoints; ++j) x[j] = arm.q_min[j] + u(rng) * (arm.q_max[j] - arm.q_min[j]);
    centroids[m] = c;
    for (int i = 0; i < 3; ++i) {
      std::vector<double> t;
      std::vector<JointVector> q;
      for (int k = 0; k < 60; ++k) {
        t.push_back(0.1 * k);
        q.push_back(c[static_cast<std::size_t>((k / (8 + i)) % 4)]);
      }
      demos.push_back(demo(std::string(m) + "_00" + std::to_string(i), featureTrajectory(c, t, q, blend),
                           keyPoseLabels(c, t, q, t)));
    }
  }
  return makePolicyData(centroids, demos);
}

// The arm, its simulation and reachableSet's demonstrations, as the execution tests use them.
struct ReachableArm {
  KeyPoseBlend blend = [] {
    KeyPoseBlend b;
    b.pole = 0.8;
    return b;
  }();
  ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  PolicyData data = reachableSet(arm, blend);
  SimModel model = makeSimModel(arm);
  double period = model.params.dt_s * model.params.substeps_per_tick;  ///< one tick, s
};

TEST_CASE("executed rollouts: the expert's labels put the servo-lagged arm on f(t+1), clean and noisy, seeded") {
  const auto& [blend, arm, data, model, period] = ReachableArm{};
  ExecutionOptions o;
  o.noisy_rollouts = 2;
  const std::vector<int> demos = {0, 4, 8};
  const std::vector<PolicySequence> a = executeDemos(data, demos, model, o, 11);
  REQUIRE(a.size() == 9);
  for (std::size_t i = 0; i < a.size(); ++i) {
    const PolicySequence& s = a[i];
    INFO("demo " << s.demo << " rollout " << s.rollout);
    CHECK(s.demo == demos[i / 3]);
    CHECK(s.rollout == static_cast<int>(i % 3));
    CHECK(s.ticks() == data.demos[static_cast<std::size_t>(s.demo)].f.size() - 1);
    CHECK(s.a_prev.front() == JointVector::Zero());
    // An independent replay on a fresh arm: the recorded states are the arm's, and from each of
    // them the label ends the tick on the target (the expert's secant stops at 1e-7 rad).
    const Replay r = replay(data, s, model);
    MESSAGE("labels on target (1e-5 rad) at " << r.ticks_on_target << " of " << r.ticks_checked
                                                << " ticks, worst miss " << r.worst_label_miss << " rad; replay |dq| "
                                                << r.worst_q_diff << ", farthest from f " << r.worst_off_trajectory << " rad");
    CHECK(r.ticks_checked == s.ticks());
    CHECK(r.worst_q_diff < 1e-9);
    // Clean rollouts follow f (their misses are the expert's own record); noisy ones leave it
    // (the states the policy's own errors reach) and are labelled back from there.
    if (s.rollout == 0) {
      CHECK(r.ticks_on_target == r.ticks_checked);
      CHECK(r.worst_label_miss <= s.worst_miss_rad + 1e-9);
      CHECK(r.worst_off_trajectory < 1e-5);
    } else {
      CHECK(r.ticks_on_target >= r.ticks_checked * 9 / 10);
      CHECK(r.worst_off_trajectory > 0.02);
    }
    // The reference input is the tick's feature-extracted target f(t+1) (clamped), and the label
    // is neither the key-pose blend of the inputs nor the step to that target: the servo lag
    // is in it.
    const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
    const std::vector<JointVector>& keys = data.centroids[static_cast<std::size_t>(d.movement)];
    double off_blend = 0.0, off_step = 0.0;
    for (std::size_t t = 1; t < s.ticks(); ++t) {
      CHECK(s.r[t] == clampToLimits(arm, d.f[t + 1]) - s.q[t]);
      const JointVector key = keys[static_cast<std::size_t>(d.label[t])];
      off_blend = std::max(off_blend, (s.a[t] - blend.velocity(s.a_prev[t], s.q[t], key)).cwiseAbs().maxCoeff());
      off_step = std::max(off_step, (s.a[t] - s.r[t]).cwiseAbs().maxCoeff());
    }
    CHECK(off_blend > 1e-3);
    CHECK(off_step > 1e-3);
  }
  // Seeded: the same seed gives the same sequences, another seed other noise (clean ones equal).
  const std::vector<PolicySequence> b = executeDemos(data, demos, model, o, 11);
  const std::vector<PolicySequence> c = executeDemos(data, demos, model, o, 12);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].q == b[i].q);
    CHECK(a[i].a == b[i].a);
    if (a[i].rollout == 0)
      CHECK(a[i].a == c[i].a);
    else
      CHECK_FALSE(a[i].q == c[i].q);
  }
  // A demo's rollouts do not depend on which other demos are listed.
  const std::vector<PolicySequence> alone = executeDemos(data, {4}, model, o, 11);
  CHECK(alone[2].a == a[5].a);

  ExecutionOptions bad = o;
  bad.noise_std_rad = {0.1, -0.2};
  CHECK_THROWS_WITH_AS(executeDemos(data, demos, model, bad, 1), doctest::Contains("negative"), UserError);
  bad = o;
  bad.noise_corr = 1.0;
  CHECK_THROWS_WITH_AS(executeDemos(data, demos, model, bad, 1), doctest::Contains("noise_corr"), UserError);
  CHECK_THROWS_WITH_AS(executeDemos(data, {99}, model, o, 1), doctest::Contains("out of range"), UserError);
}

namespace {

// Policies that keep their momentum and push past the target (the autonomous failure):
// stateless functions of their inputs, so a test can recompute every action. `push` rad per
// tick on the movement's joint drives it into its limits (the clamp).
JointVector driftingLaw(double push, int movement, const JointVector& q, const JointVector& a_prev, const JointVector& r) {
  JointVector a = 0.9 * a_prev + 0.3 * r;
  for (int j = 0; j < kNumJoints; ++j) a[j] += 0.01 * (movement + 1) + 0.02 * std::sin(3.0 * q[j]);
  a[movement] += push;
  return a;
}

// The controller's command for action a at q, recomputed independently: q + a inside the
// position limits and one period's reach. `saturated` counts the clamped joints.
JointVector clampedCommand(const ArmModel& arm, double period, const JointVector& q, const JointVector& a,
                           std::size_t& saturated) {
  JointVector c;
  for (int j = 0; j < kNumJoints; ++j) {
    const double step = arm.v_max[j] * period;
    const double lo = std::max(arm.q_min[j], q[j] - step), hi = std::min(arm.q_max[j], q[j] + step);
    c[j] = std::clamp(q[j] + a[j], std::min(lo, hi), std::max(lo, hi));
    if (c[j] != q[j] + a[j]) ++saturated;
  }
  return c;
}

}  // namespace

TEST_CASE("DAgger rollouts execute the policy's clamped action and the expert labels the states it reaches") {
  const auto& [blend, arm, data, model, period] = ReachableArm{};
  const ExecutionOptions o;
  const auto law = driftingLaw;
  const std::vector<int> demos = {1, 5, 7};
  for (const double push : {0.0, 0.3}) {
    INFO("push " << push);
    std::vector<int> starts;  // t == 0 once per rollout, then t counts up
    int expect_t = 0;
    bool ticks_in_order = true;
    const RolloutPolicy policy = [&](int movement, int t, const JointVector& q, const JointVector& a_prev,
                                     const JointVector& r) -> JointVector {
      if (t == 0) {
        starts.push_back(movement);
        expect_t = 0;
      }
      ticks_in_order = ticks_in_order && t == expect_t++;
      return law(push, movement, q, a_prev, r);
    };
    const std::vector<PolicySequence> seqs = executePolicyRollouts(data, demos, model, o, policy, 2);
    REQUIRE(seqs.size() == demos.size());
    CHECK(ticks_in_order);
    REQUIRE(starts.size() == demos.size());
    std::size_t saturated = 0;
    for (std::size_t i = 0; i < seqs.size(); ++i) {
      const PolicySequence& s = seqs[i];
      const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
      INFO("demo " << s.demo);
      CHECK(s.demo == demos[i]);
      CHECK(s.rollout == -2);
      CHECK(starts[i] == d.movement);
      REQUIRE(s.ticks() == d.f.size() - 1);
      CHECK((s.q.front() - d.f.front()).cwiseAbs().maxCoeff() < 1e-9);
      CHECK(s.a_prev.front() == JointVector::Zero());
      // (b) The executed command (q(t) + the next a(t−1)) is the policy's action as the
      // controller applies it: q + a inside the position limits and one period's reach.
      double worst_exec = 0.0;
      for (std::size_t t = 0; t + 1 < s.ticks(); ++t) {
        CHECK(s.r[t] == clampToLimits(arm, d.f[t + 1]) - s.q[t]);
        const JointVector c =
            clampedCommand(arm, period, s.q[t], law(push, d.movement, s.q[t], s.a_prev[t], s.r[t]), saturated);
        worst_exec = std::max(worst_exec, (s.q[t] + s.a_prev[t + 1] - c).cwiseAbs().maxCoeff());
      }
      CHECK(worst_exec < 1e-12);
      // (a) An independent replay on a fresh arm: the recorded states are the arm's under those
      // commands, the labels are the expert's from exactly those states (the replay reproduces
      // its recorded misses), and where the policy stays within reach they end the tick on f(t+1).
      const Replay r = replay(data, s, model);
      MESSAGE("policy rollout (push " << push << "): labels on target (1e-5 rad) at " << r.ticks_on_target << " of "
                                      << r.ticks_checked << " ticks; drift " << s.drift_rad << " rad, expert's worst miss "
                                      << s.worst_miss_rad << " rad");
      CHECK(r.ticks_checked == s.ticks());
      CHECK(r.worst_q_diff < 1e-9);
      CHECK(r.worst_label_miss <= s.worst_miss_rad + 1e-9);
      CHECK(s.drift_rad >= r.worst_off_trajectory - 1e-9);
      CHECK(r.worst_off_trajectory > 0.02);  // the policy's own states, off the demonstration
      if (push == 0.0) CHECK(r.ticks_on_target >= r.ticks_checked / 2);
    }
    if (push > 0.0) CHECK(saturated > 0);  // the clamp was exercised
  }
  // Deterministic: the same policy gives the same sequences.
  const RolloutPolicy mild = [&](int movement, int, const JointVector& q, const JointVector& a_prev,
                                 const JointVector& r) -> JointVector { return law(0.0, movement, q, a_prev, r); };
  const std::vector<PolicySequence> a = executePolicyRollouts(data, demos, model, o, mild, 1);
  const std::vector<PolicySequence> b = executePolicyRollouts(data, demos, model, o, mild, 1);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].q == b[i].q);
    CHECK(a[i].a == b[i].a);
  }
  // Without labels (scoring): the same states to the last bit, only the expert's work skipped.
  for (const double push : {0.0, 0.3}) {
    const RolloutPolicy p = [&](int movement, int, const JointVector& q, const JointVector& a_prev,
                                const JointVector& r) -> JointVector { return law(push, movement, q, a_prev, r); };
    const std::vector<PolicySequence> with = executePolicyRollouts(data, demos, model, o, p, 0);
    const std::vector<PolicySequence> without = executePolicyRollouts(data, demos, model, o, p, 0, false);
    REQUIRE(without.size() == with.size());
    for (std::size_t i = 0; i < with.size(); ++i) {
      INFO("push " << push << " demo " << with[i].demo);
      CHECK(without[i].q == with[i].q);
      CHECK(without[i].a_prev == with[i].a_prev);
      CHECK(without[i].r == with[i].r);
      CHECK(without[i].drift_rad == with[i].drift_rad);
      CHECK(without[i].a.empty());
      CHECK(with[i].a.size() == with[i].q.size());
    }
  }
  ExecutionOptions mixed = o;
  mixed.dagger_beta = 0.5;
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, mixed, mild, 1, false), doctest::Contains("labels"), UserError);
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, {99}, model, o, mild, 1), doctest::Contains("out of range"), UserError);
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, o, RolloutPolicy{}, 1), doctest::Contains("no policy"),
                       UserError);
}

TEST_CASE("beta-mixed DAgger rollouts: expert ticks execute the label, beta 1 is the clean execution, round 0 stays pure") {
  const auto& [blend, arm, data, model, period] = ReachableArm{};
  // A policy that drifts (momentum plus a push): far from the expert on every tick.
  const auto law = [](int movement, const JointVector& q, const JointVector& a_prev, const JointVector& r) {
    return driftingLaw(0.1, movement, q, a_prev, r);
  };
  const RolloutPolicy policy = [&](int movement, int, const JointVector& q, const JointVector& a_prev,
                                   const JointVector& r) -> JointVector { return law(movement, q, a_prev, r); };
  const std::vector<int> demos = {1, 5, 7};

  SUBCASE("beta 1: every tick is the expert's, so the rollout is the clean execution, field for field") {
    ExecutionOptions o;
    o.noisy_rollouts = 0;
    const std::vector<PolicySequence> clean = executeDemos(data, demos, model, o, 1);
    o.dagger_beta = 1.0;
    const std::vector<PolicySequence> mixed = executePolicyRollouts(data, demos, model, o, policy, 1);
    REQUIRE(mixed.size() == clean.size());
    for (std::size_t i = 0; i < mixed.size(); ++i) {
      CHECK(mixed[i].expert_ticks == mixed[i].ticks());
      CHECK(mixed[i].q == clean[i].q);
      CHECK(mixed[i].a_prev == clean[i].a_prev);
      CHECK(mixed[i].r == clean[i].r);
      CHECK(mixed[i].a == clean[i].a);
    }
  }

  SUBCASE("beta 0.5: round i executes the expert on about 0.5^i of the ticks, the policy's clamped action on the rest") {
    ExecutionOptions o;
    o.dagger_beta = 0.5;
    std::vector<std::vector<PolicySequence>> rounds;
    for (int round = 0; round <= 2; ++round) {
      const std::vector<PolicySequence> seqs = executePolicyRollouts(data, demos, model, o, policy, round);
      std::size_t ticks = 0, expert = 0, seen_expert = 0, seen_policy = 0;
      for (const PolicySequence& s : seqs) {
        ticks += s.ticks();
        expert += s.expert_ticks;
        // Which command ran is seen in the next tick's a(t−1): the label (expert) or the law's
        // action inside the controller's bounds (policy); the two differ on these ticks.
        for (std::size_t t = 0; t + 1 < s.ticks(); ++t) {
          std::size_t clamped = 0;
          const JointVector c = clampedCommand(arm, period, s.q[t], law(s.movement, s.q[t], s.a_prev[t], s.r[t]), clamped);
          const bool by_expert = s.a_prev[t + 1] == s.a[t];
          const bool by_policy = (s.q[t] + s.a_prev[t + 1] - c).cwiseAbs().maxCoeff() < 1e-12;
          CHECK(by_expert != by_policy);
          seen_expert += by_expert ? 1 : 0;
          seen_policy += by_policy ? 1 : 0;
        }
      }
      INFO("round " << round << ": " << expert << " of " << ticks << " ticks by the expert");
      // The last tick's command leaves no a(t−1) behind: at most one per sequence unseen.
      CHECK(seen_expert <= expert);
      CHECK(expert <= seen_expert + seqs.size());
      CHECK(seen_expert + seen_policy + seqs.size() == ticks);
      const double p = round == 0 ? 0.0 : std::pow(0.5, round);
      const double sd = std::sqrt(static_cast<double>(ticks) * p * (1.0 - p));
      CHECK(std::abs(static_cast<double>(expert) - p * static_cast<double>(ticks)) <= 4.0 * sd);
      if (round == 0) CHECK(expert == 0);  // rollout scoring is always the pure policy
      rounds.push_back(seqs);
    }
    // A drift bound ends each round's rollout before the first tick past it; scoring (round 0)
    // is never cut. The policy pushes off by ~0.1 rad a tick, so the bound is reached early.
    ExecutionOptions bounded = o;
    bounded.dagger_max_drift_rad = 0.05;
    const std::vector<PolicySequence> cut = executePolicyRollouts(data, demos, model, bounded, policy, 2);
    const std::vector<PolicySequence> whole = executePolicyRollouts(data, demos, model, bounded, policy, 0);
    for (std::size_t i = 0; i < cut.size(); ++i) {
      const PolicyDemo& d = data.demos[static_cast<std::size_t>(cut[i].demo)];
      INFO("bounded demo " << cut[i].demo);
      CHECK(whole[i].ticks() == d.f.size() - 1);
      REQUIRE(cut[i].ticks() >= 1);
      CHECK(cut[i].ticks() < d.f.size() - 1);
      // Every kept state is within the bound; the unbounded round 2 (same seed stream) passes it
      // at exactly the tick where the cut one ends, and agrees with it before.
      for (std::size_t t = 0; t < cut[i].ticks(); ++t)
        CHECK((cut[i].q[t] - clampToLimits(arm, d.f[t])).cwiseAbs().maxCoeff() <= 0.05);
      const PolicySequence& full = rounds[2][i];
      REQUIRE(full.ticks() > cut[i].ticks());
      const std::size_t n = cut[i].ticks();
      CHECK((full.q[n] - clampToLimits(arm, d.f[n])).cwiseAbs().maxCoeff() > 0.05);
      CHECK(std::equal(cut[i].a.begin(), cut[i].a.end(), full.a.begin()));
      CHECK(cut[i].drift_rad > 0.05);  // the drift that ended it is reported
    }
    // Seeded: the same round again gives the same sequences.
    const std::vector<PolicySequence> again = executePolicyRollouts(data, demos, model, o, policy, 2);
    for (std::size_t i = 0; i < again.size(); ++i) {
      CHECK(again[i].q == rounds[2][i].q);
      CHECK(again[i].expert_ticks == rounds[2][i].expert_ticks);
    }
  }
}

namespace {

// The aligned point of a state, by brute force over every tick of every clean execution of the
// movement in the pool: ExecutionOptions::dagger_align_band's definition written out again here
// (the test's oracle; the velocity of a mismatch weighs as if carried on for 2 ticks). `target`
// is the successor label's aim for return share `ret`, `command` the clean execution's command.
struct AlignedPoint {
  JointVector target = JointVector::Zero(), command = JointVector::Zero();
  double distance = 0.0;
  bool found = false;
};

AlignedPoint alignedOracle(const PolicyData& data, const std::vector<PolicySequence>& pool, const ArmModel& arm,
                           int movement, std::size_t t, const JointVector& q, const JointVector& q_before, int band,
                           double ret) {
  AlignedPoint p;
  double best = 0.0;
  for (const PolicySequence& seq : pool) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(seq.demo)];
    if (demo.movement != movement || seq.rollout != 0) continue;
    for (std::size_t k = 0; k < seq.ticks(); ++k) {
      if (std::abs(static_cast<double>(k) - static_cast<double>(t)) > band) continue;
      const JointVector at = clampToLimits(arm, demo.f[k]);
      const JointVector prev = clampToLimits(arm, demo.f[k == 0 ? 0 : k - 1]);
      double cost = 0.0;
      for (int j = 0; j < kNumJoints; ++j) {
        const double dp = q[j] - at[j], dv = 2.0 * ((q[j] - q_before[j]) - (at[j] - prev[j]));
        cost += dp * dp + dv * dv;
      }
      if (!p.found || cost < best) {
        best = cost;
        p.found = true;
        p.distance = (q - at).cwiseAbs().maxCoeff();
        p.target = clampToLimits(arm, JointVector(clampToLimits(arm, demo.f[k + 1]) + (1.0 - ret) * (q - at)));
        p.command = seq.q[k] + seq.a[k];
      }
    }
  }
  return p;
}

}  // namespace

TEST_CASE("aligned DAgger labels aim at the nearest demonstration point's successor, not the clock's f(t+1)") {
  // Per movement 3 demonstrations, 8, 9 and 10 ticks a key pose.
  const auto& [blend, arm, data, model, period] = ReachableArm{};
  const RolloutPolicy policy = [](int movement, int, const JointVector& q, const JointVector& a_prev,
                                  const JointVector& r) -> JointVector { return driftingLaw(0.0, movement, q, a_prev, r); };
  std::vector<int> all(data.demos.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  ExecutionOptions with_noisy;  // the noisy rollouts in a pool are not aligned to
  const std::vector<PolicySequence> pool = executeDemos(data, all, model, with_noisy, 3);
  const std::vector<int> demos = {1, 5, 7};
  ExecutionOptions o;
  o.dagger_align_band = 5;
  o.dagger_return = 0.5;
  const std::vector<PolicySequence> seqs = executePolicyRollouts(data, demos, model, o, policy, 1, true, pool);
  const std::vector<PolicySequence> clock = executePolicyRollouts(data, demos, model, ExecutionOptions{}, policy, 1);
  REQUIRE(seqs.size() == demos.size());
  std::size_t moved = 0;  // ticks whose aligned target is off the clock's and whose label ends on it
  for (std::size_t i = 0; i < seqs.size(); ++i) {
    const PolicySequence& s = seqs[i];
    const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
    INFO("demo " << s.demo);
    REQUIRE(s.ticks() == d.f.size() - 1);
    // The policy's states do not depend on the labels (no β): the clock's round visits them too.
    CHECK(s.q == clock[i].q);
    CHECK(s.a != clock[i].a);
    std::vector<AlignedPoint> points;
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      CHECK(s.r[t] == clampToLimits(arm, d.f[t + 1]) - s.q[t]);  // the input stays the clock's
      points.push_back(alignedOracle(data, pool, arm, s.movement, t, s.q[t], s.q[t == 0 ? 0 : t - 1], 5, 0.5));
      REQUIRE(points.back().found);
    }
    const Replay r = replay(data, s, model, [&](std::size_t t) { return points[t].target; });
    MESSAGE("aligned labels: on the oracle's target (1e-5 rad) at " << r.ticks_on_target << " of " << r.ticks_checked
                                                                    << " ticks; expert's worst miss " << s.worst_miss_rad);
    CHECK(r.worst_q_diff < 1e-9);
    CHECK(r.worst_label_miss <= s.worst_miss_rad + 1e-9);
    CHECK(r.ticks_on_target >= r.ticks_checked / 2);
    // Count the ticks that tell the two apart: the label ends on the aligned target, far from f(t+1).
    SimData sim(model, d.f.front());
    SimSnapshot snap;
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      captureSim(sim, snap);
      const JointVector end = stepSim(model, sim, sim.q + s.a[t]);
      restoreSim(sim, snap);
      if ((end - points[t].target).cwiseAbs().maxCoeff() < 1e-5 &&
          (end - clampToLimits(arm, d.f[t + 1])).cwiseAbs().maxCoeff() > 1e-3)
        ++moved;
      stepSim(model, sim, t + 1 < s.ticks() ? JointVector(s.q[t] + s.a_prev[t + 1]) : JointVector(sim.q + s.a[t]));
    }
  }
  MESSAGE("ticks labelled toward an aligned point 1 mrad or more from the clock's: " << moved);
  CHECK(moved > 20);

  // The labels do not depend on which share of the demonstrations is rolled out.
  const std::vector<PolicySequence> alone = executePolicyRollouts(data, {5}, model, o, policy, 1, true, pool);
  CHECK(alone.front().a == seqs[1].a);

  // The drift bound measures the distance to the aligned point: every kept tick within it, the
  // unbounded round past it exactly where the bounded one ends.
  ExecutionOptions bounded = o;
  bounded.dagger_max_drift_rad = 0.01;
  const std::vector<PolicySequence> cut = executePolicyRollouts(data, demos, model, bounded, policy, 1, true, pool);
  std::size_t ended = 0;
  for (std::size_t i = 0; i < cut.size(); ++i) {
    const PolicySequence& c = cut[i];
    INFO("bounded demo " << c.demo);
    REQUIRE(c.ticks() >= 1);
    for (std::size_t t = 0; t < c.ticks(); ++t)
      CHECK(alignedOracle(data, pool, arm, c.movement, t, c.q[t], c.q[t == 0 ? 0 : t - 1], 5, 0.5).distance <= 0.01);
    CHECK(std::equal(c.a.begin(), c.a.end(), seqs[i].a.begin()));
    const std::size_t n = c.ticks();
    if (n < seqs[i].ticks()) {
      ++ended;
      CHECK(alignedOracle(data, pool, arm, c.movement, n, seqs[i].q[n], seqs[i].q[n - 1], 5, 0.5).distance > 0.01);
    }
  }
  CHECK(ended > 0);  // the bound was reached

  // Command labels: the clean execution's command at the aligned point, inside the controller's
  // bounds at the state reached; no expert search (the servo does the returning).
  ExecutionOptions command = o;
  command.dagger_align_label = ExecutionOptions::AlignLabel::kCommand;
  const std::vector<PolicySequence> commanded = executePolicyRollouts(data, demos, model, command, policy, 1, true, pool);
  std::size_t differ = 0, saturated = 0;
  for (std::size_t i = 0; i < commanded.size(); ++i) {
    const PolicySequence& c = commanded[i];
    INFO("commanded demo " << c.demo);
    CHECK(c.q == seqs[i].q);  // the policy's states again
    double worst = 0.0;
    for (std::size_t t = 0; t < c.ticks(); ++t) {
      const AlignedPoint p = alignedOracle(data, pool, arm, c.movement, t, c.q[t], c.q[t == 0 ? 0 : t - 1], 5, 0.5);
      const JointVector bounded_command = clampedCommand(arm, period, c.q[t], JointVector(p.command - c.q[t]), saturated);
      worst = std::max(worst, (c.q[t] + c.a[t] - bounded_command).cwiseAbs().maxCoeff());
      if ((c.a[t] - seqs[i].a[t]).cwiseAbs().maxCoeff() > 1e-3) ++differ;
    }
    CHECK(worst < 1e-12);
  }
  CHECK(differ > 20);  // not the successor labels

  // Scoring (round 0, no labels) never aligns and needs no pool; labelled rounds do.
  const std::vector<PolicySequence> scored = executePolicyRollouts(data, demos, model, o, policy, 0, false);
  CHECK(scored.front().q == executePolicyRollouts(data, demos, model, ExecutionOptions{}, policy, 0, false).front().q);
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, o, policy, 1), doctest::Contains("align"), UserError);
  std::vector<PolicySequence> noisy_only;
  for (const PolicySequence& p : pool)
    if (p.rollout != 0) noisy_only.push_back(p);
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, o, policy, 1, true, noisy_only), doctest::Contains("clean"),
                       UserError);
  // Only the clean executions count: the pool without its noisy rollouts gives the same labels.
  std::vector<PolicySequence> clean_pool;
  for (const PolicySequence& p : pool)
    if (p.rollout == 0) clean_pool.push_back(p);
  CHECK(executePolicyRollouts(data, demos, model, o, policy, 1, true, clean_pool).back().a == seqs.back().a);
  ExecutionOptions bad = o;
  bad.dagger_return = 0.0;
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, bad, policy, 1, true, pool),
                       doctest::Contains("dagger_return"), UserError);
  bad.dagger_return = 1.5;
  CHECK_THROWS_AS(executePolicyRollouts(data, demos, model, bad, policy, 1, true, pool), UserError);
  bad = o;
  bad.dagger_align_band = -1;
  CHECK_THROWS_WITH_AS(executePolicyRollouts(data, demos, model, bad, policy, 1, true, pool),
                       doctest::Contains("dagger_align_band"), UserError);
}
