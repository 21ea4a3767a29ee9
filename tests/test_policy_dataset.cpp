// The policy's training data (docs/policy.md "Data"): the split is by demonstration, statistics
// come from the training split only, baselines match an independent computation, the split and
// the fingerprint are deterministic, bad files are named; the demonstrators' starts (retarget.csv)
// and the trajectories restarted there; the expert's executed rollouts and a policy's runs on the
// simulated arm, replayed independently.
#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/sim_arm.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
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

// Sequences of an arm that follows f exactly: q(t) = f(t), r(t) = f(t+1) − f(t), and as label a
// lagged step a(t) = r(t) + 0.1 a(t−1), the applied a(t−1) being the last label.
std::vector<PolicySequence> trajectorySequences(const PolicyData& data, const std::vector<int>& demos) {
  std::vector<PolicySequence> out;
  for (int d : demos) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    PolicySequence s;
    s.demo = d;
    s.movement = demo.movement;
    JointVector a_prev = JointVector::Zero();
    for (std::size_t t = 0; t + 1 < demo.f.size(); ++t) {
      const JointVector r = demo.f[t + 1] - demo.f[t];
      const JointVector a = r + 0.1 * a_prev;
      s.q.push_back(demo.f[t]);
      s.a_prev.push_back(a_prev);
      s.r.push_back(r);
      s.a.push_back(a);
      a_prev = a;
    }
    out.push_back(s);
  }
  return out;
}

}  // namespace

TEST_CASE("the standard movements get indices elbow = 0, whole_arm = 1, wrist = 2") {
  const PolicyData data = standardSet(1);
  CHECK(data.movement_names == std::vector<std::string>{"elbow", "whole_arm", "wrist"});
  for (const PolicyDemo& d : data.demos)
    CHECK(data.movement_names[static_cast<std::size_t>(d.movement)] + "_000" == d.name);
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
  // No tick of a validation demo is among the training sequences.
  for (const PolicySequence& s : trajectorySequences(data, split.train)) CHECK(val.count(s.demo) == 0);

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
  const NormStats before = normStats(trajectorySequences(data, split.train));

  // Independent computation straight from f: mean and population std of q = f(t), of the label
  // a = f(t+1) − f(t) + 0.1 a(t−1) and of r = f(t+1) − f(t), t < n-1.
  for (int j = 0; j < kNumJoints; ++j) {
    std::vector<double> qs, as, rs;
    for (int d : split.train) {
      const auto& f = data.demos[static_cast<std::size_t>(d)].f;
      double a_prev = 0.0;
      for (std::size_t t = 0; t + 1 < f.size(); ++t) {
        const double step = f[t + 1][j] - f[t][j], a = step + 0.1 * a_prev;
        qs.push_back(f[t][j]);
        as.push_back(a);
        rs.push_back(step);
        a_prev = a;
      }
    }
    const auto meanStd = [](const std::vector<double>& x) {
      double sum = 0.0, var = 0.0;
      for (double v : x) sum += v;
      const double mean = sum / static_cast<double>(x.size());
      for (double v : x) var += (v - mean) * (v - mean);
      return std::make_pair(mean, std::sqrt(var / static_cast<double>(x.size())));
    };
    const auto [q_mean, q_std] = meanStd(qs);
    const auto [a_mean, a_std] = meanStd(as);
    const auto [r_mean, r_std] = meanStd(rs);
    CHECK(before.q_mean[j] == doctest::Approx(q_mean).epsilon(1e-12));
    CHECK(before.q_std[j] == doctest::Approx(q_std).epsilon(1e-12));
    CHECK(before.a_mean[j] == doctest::Approx(a_mean).epsilon(1e-12));
    CHECK(before.a_std[j] == doctest::Approx(a_std).epsilon(1e-12));
    CHECK(before.r_mean[j] == doctest::Approx(r_mean).epsilon(1e-12));
    CHECK(before.r_std[j] == doctest::Approx(r_std).epsilon(1e-12));
  }

  // Wildly different validation demos leave the statistics bit-for-bit unchanged.
  for (int d : split.val)
    for (JointVector& q : data.demos[static_cast<std::size_t>(d)].f) q *= 100.0;
  const NormStats after = normStats(trajectorySequences(data, splitByDemonstration(data, 0.2, 3).train));
  CHECK(after.q_mean == before.q_mean);
  CHECK(after.q_std == before.q_std);
  CHECK(after.a_mean == before.a_mean);
  CHECK(after.a_std == before.a_std);
  CHECK(after.r_mean == before.r_mean);
  CHECK(after.r_std == before.r_std);
  CHECK_THROWS_AS(normStats({}), UserError);
}

TEST_CASE("a constant joint gets the floored standard deviation, never 0") {
  const PolicyData data = makePolicyData({{"m", {JointVector::Zero()}}},
                                         {demo("m_0", {JointVector::Ones(), JointVector::Ones(), JointVector::Ones()}, {0, 0, 0})});
  const NormStats st = normStats(trajectorySequences(data, {0}));
  CHECK(st.q_std == JointVector::Constant(kMinStd));
  CHECK(st.a_std == JointVector::Constant(kMinStd));
  CHECK(st.r_std == JointVector::Constant(kMinStd));
}

TEST_CASE("baselines equal an independent hand computation from the trajectories: zero action, repeat last, gain law") {
  const PolicyData data = standardSet(3);
  const double g = 1.0894;
  double zero = 0.0, repeat = 0.0, law = 0.0, count = 0.0;
  for (const PolicyDemo& d : data.demos)
    for (int j = 0; j < kNumJoints; ++j) {
      double a_prev = 0.0;
      for (std::size_t t = 0; t + 1 < d.f.size(); ++t) {
        const double r = d.f[t + 1][j] - d.f[t][j], a = r + 0.1 * a_prev;
        zero += a * a;
        repeat += (a - a_prev) * (a - a_prev);
        law += (a - g * r) * (a - g * r);
        count += 1;
        a_prev = a;
      }
    }
  const Baselines b = baselines(trajectorySequences(data, allDemos(data)), g);
  CHECK(b.zero_action == doctest::Approx(zero / count).epsilon(1e-12));
  CHECK(b.repeat_last == doctest::Approx(repeat / count).epsilon(1e-12));
  CHECK(b.gain_law == doctest::Approx(law / count).epsilon(1e-12));
  // Smooth trajectories: repeating the last action beats predicting none; the law's gain matters.
  CHECK(b.repeat_last < b.zero_action);
  CHECK(baselines(trajectorySequences(data, allDemos(data)), 1.0).gain_law != b.gain_law);
  const Baselines none = baselines({}, g);
  CHECK((none.zero_action == 0.0 && none.repeat_last == 0.0 && none.gain_law == 0.0));
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

TEST_CASE("makePolicyData sorts movements and demonstrations by name, indexes the movements, and fills a missing measured column with 1 and a missing start with f(0)") {
  const JointVector c0 = jv(0, 0, 0, 0, 0), c1 = jv(1, 2, 3, 4, 5);
  const JointVector f0 = jv(0.1, 0.2, 0.3, 0.4, 0.5), f1 = jv(0.2, 0.2, 0.1, 0.4, 0.9), f2 = jv(0.0, 0.5, 0.1, 0.3, 0.9);
  PolicyDemo started = demo("a_000", {f2, f0}, {1, 0});
  started.start = jv(0.3, 0.1, 0.2, 0.0, 0.4);
  // "b_000" sorts after "a_000": the first movement (by name) is "a" -> index 0.
  const PolicyData data = makePolicyData({{"b", {c0, c1}}, {"a", {c1, c0}}}, {demo("b_000", {f0, f1, f2}, {0, 1, 1}), started});
  REQUIRE(data.movement_names == std::vector<std::string>{"a", "b"});
  REQUIRE(data.demos.size() == 2);
  CHECK(data.centroids[0][0] == c1);
  CHECK(data.demos[0].name == "a_000");
  CHECK(data.demos[0].movement == 0);
  CHECK(data.demos[1].movement == 1);
  CHECK(data.demos[1].measured == std::vector<std::uint8_t>{1, 1, 1});  // missing column = all measured
  CHECK(data.demos[0].start == jv(0.3, 0.1, 0.2, 0.0, 0.4));
  CHECK(data.demos[1].start == f0);  // unset: f(0)
  PolicyDemo bad = demo("a_001", {f0, f1}, {0, 0});
  bad.start = jv(0.1, 0.2, std::numeric_limits<double>::infinity(), 0.0, 0.0);
  CHECK_THROWS_WITH_AS(makePolicyData({{"a", {c0}}}, {bad}), doctest::Contains("non-finite start"), UserError);
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
  PolicyData s = standardSet(2);
  s.demos[1].start[4] += 1e-12;
  CHECK(dataFingerprint(a) != dataFingerprint(s));
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
  // No retarget.csv beside features.csv: the start is f(0).
  CHECK(data.demos[0].start == JointVector::Ones());
  CHECK(data.demos[1].start == JointVector::Zero());
}

TEST_CASE("loadPolicyData reads each start from retarget.csv: the retargeted pose at the first measured sample") {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests" / ("policy_data_starts_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  writeText(dir / "centroids.json", centroidsJson());
  // wrist_000: the first two samples held (no human), the first measured one at t = 0.2 s.
  writeText(dir / "wrist_000" / "features.csv",
            "t_s,label,measured,f_0,f_1,f_2,f_3,f_4\n"
            "0,0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0,0\n0.2,1,1,0.1,0.1,0.1,0.1,0.1\n0.3,1,1,0.2,0.2,0.2,0.2,0.2\n");
  writeText(dir / "wrist_000" / "retarget.csv",
            "t_s,qr_0,qr_1,qr_2,qr_3,qr_4,step_bound\n"
            "0,9,9,9,9,9,0\n0.1,9,9,9,9,9,0\n0.2,0.31,-0.42,1.05,0.6,-0.07,0\n0.3,8,8,8,8,8,0\n");
  // elbow_000: every sample measured; the columns in another order, other columns beside them.
  writeText(dir / "elbow_000" / "features.csv", "t_s,label,f_0,f_1,f_2,f_3,f_4\n0,1,1,1,1,1,1\n0.1,0,2,2,2,2,2\n");
  writeText(dir / "elbow_000" / "retarget.csv",
            "qr_4,t_s,x,qr_0,qr_1,qr_2,qr_3\n0.5,0,7,0.1,0.2,0.3,0.4\n9,0.1,7,9,9,9,9\n");
  const PolicyData data = loadPolicyData(dir.string());
  REQUIRE(data.demos.size() == 2);
  CHECK(data.demos[0].name == "elbow_000");
  CHECK(data.demos[0].start == jv(0.1, 0.2, 0.3, 0.4, 0.5));
  CHECK(data.demos[1].start == jv(0.31, -0.42, 1.05, 0.6, -0.07));
  CHECK(data.demos[1].f.front() == JointVector::Zero());  // f itself is untouched

  // A retarget.csv without a row at the first measured sample is named, with the time.
  writeText(dir / "wrist_000" / "retarget.csv", "t_s,qr_0,qr_1,qr_2,qr_3,qr_4\n0,9,9,9,9,9\n0.3,8,8,8,8,8\n");
  const std::string e = loadError(dir.string());
  CHECK_MESSAGE(e.find("wrist_000/retarget.csv: no row at t_s 0.2") != std::string::npos, e);
  CHECK(e.find('\n') == std::string::npos);
  writeText(dir / "wrist_000" / "retarget.csv", "t_s,qr_0,qr_1,qr_2,qr_3\n0.2,1,1,1,1\n");
  CHECK(loadError(dir.string()).find("qr_4") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("fromOwnStarts restarts f from rest at the start: f(0) = start, the key-pose blend from there converges to f, and a start at f(0) gives f exactly") {
  // f of a data set made by the blend (the default pole) from labels that agree with its own.
  const PolicyData data = blendedSet(KeyPoseBlend{});
  PolicyData moved = data;
  std::mt19937_64 rng(5);
  for (PolicyDemo& d : moved.demos)
    for (int j = 0; j < kNumJoints; ++j) d.start[j] = d.f.front()[j] + 0.15 * (2.0 * static_cast<double>(rng() >> 11) * 0x1.0p-53 - 1.0);
  const PolicyData own = fromOwnStarts(moved);
  const PolicyData same = fromOwnStarts(data);  // every start is f(0)
  REQUIRE(own.demos.size() == data.demos.size());
  const double pole = kFeatureBlendPole;
  double worst_decay = 0.0, worst_late = 0.0, largest_offset = 0.0;
  for (std::size_t i = 0; i < data.demos.size(); ++i) {
    const PolicyDemo &d = data.demos[i], &o = own.demos[i];
    CAPTURE(d.name);
    CHECK(same.demos[i].f == d.f);
    REQUIRE(o.f.size() == d.f.size());
    CHECK(o.f.front() == moved.demos[i].start);
    CHECK(o.label == d.label);
    CHECK(o.t_s == d.t_s);
    // Both start at rest and follow the same key poses: their difference decays as a critically
    // damped pair from rest, e0 (1 + (1 − pole) n) poleⁿ (docs: KeyPoseBlend).
    const JointVector e0 = moved.demos[i].start - d.f.front();
    largest_offset = std::max(largest_offset, e0.cwiseAbs().maxCoeff());
    for (std::size_t n = 0; n < d.f.size(); ++n) {
      const double factor = (1.0 + (1.0 - pole) * static_cast<double>(n)) * std::pow(pole, static_cast<double>(n));
      worst_decay = std::max(worst_decay, ((o.f[n] - d.f[n]) - factor * e0).cwiseAbs().maxCoeff());
      if (n >= 20) worst_late = std::max(worst_late, (o.f[n] - d.f[n]).cwiseAbs().maxCoeff());
    }
  }
  MESSAGE("starts up to " << largest_offset << " rad off f(0): after 20 ticks within " << worst_late << " rad");
  CHECK(largest_offset > 0.1);
  CHECK(worst_decay < 1e-12);
  CHECK(worst_late < 1e-3);
  CHECK(dataFingerprint(own) != dataFingerprint(moved));
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

// Replays a rollout on a fresh simulated arm with the commands it applied (q(t) + a(t−1) of the
// next tick) and, at every tick, tries the label from a snapshot of the replayed state: returns
// the largest |q(t+1) − f(t+1)| the labels leave over the ticks whose clamped target is within
// one tick's reach, and the largest difference between the replayed and the recorded q.
struct Replay {
  double worst_label_miss = 0.0, worst_q_diff = 0.0, worst_off_trajectory = 0.0;
  std::size_t ticks_checked = 0, ticks_on_target = 0;  ///< label ends within 1e-5 rad of f(t+1)
};

Replay replay(const PolicyData& data, const PolicySequence& s, const SimModel& model) {
  const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
  const ArmModel& arm = model.arm;
  SimData sim(model, d.f.front());
  SimSnapshot snap;
  Replay r;
  for (std::size_t t = 0; t < s.ticks(); ++t) {
    r.worst_q_diff = std::max(r.worst_q_diff, (sim.q - s.q[t]).cwiseAbs().maxCoeff());
    const JointVector target = clampToLimits(arm, d.f[t + 1]);
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
  bad.noise_corr = 1.0;
  CHECK_THROWS_WITH_AS(executeDemos(data, demos, model, bad, 1), doctest::Contains("noise_corr"), UserError);
  CHECK_THROWS_WITH_AS(executeDemos(data, {99}, model, o, 1), doctest::Contains("out of range"), UserError);
}

TEST_CASE("noisy rollouts from other demonstrations' starts: another listed one's of the same movement (its own when none is listed), labelled toward f(t+1)") {
  const auto& [blend, arm, same_starts, model, period] = ReachableArm{};
  // Each demonstration from a start of its own (0.1 rad apart on every joint), as recorded ones.
  PolicyData moved = same_starts;
  for (std::size_t i = 0; i < moved.demos.size(); ++i)
    moved.demos[i].start = moved.demos[i].f.front() + JointVector::Constant(0.1 * (static_cast<double>(i % 3) - 1.0));
  const PolicyData data = fromOwnStarts(moved);
  ExecutionOptions o;
  o.noisy_rollouts = 2;
  o.other_starts = true;
  // Three elbow demonstrations and one whole_arm demonstration alone of its movement.
  const std::vector<int> demos = {0, 1, 2, 3};
  const std::vector<PolicySequence> a = executeDemos(data, demos, model, o, 5);
  REQUIRE(a.size() == 12);
  for (const PolicySequence& s : a) {
    INFO("demo " << s.demo << " rollout " << s.rollout);
    const PolicyDemo& d = data.demos[static_cast<std::size_t>(s.demo)];
    const auto at = [&](int e) {
      return (s.q.front() - data.demos[static_cast<std::size_t>(e)].f.front()).cwiseAbs().maxCoeff() < 1e-9;
    };
    // Every tick's target (q + r) is the demonstration's f(t+1), clamped, whatever the start.
    for (std::size_t t = 0; t < s.ticks(); ++t) CHECK(s.r[t] == clampToLimits(arm, d.f[t + 1]) - s.q[t]);
    if (s.rollout == 0) {
      CHECK(at(s.demo));
      continue;
    }
    // The start: another listed demonstration's of the same movement; its own when none is listed.
    if (s.demo == 3) {
      CHECK(at(3));
    } else {
      CHECK_FALSE(at(s.demo));
      CHECK((at(0) || at(1) || at(2)));
    }
  }
  // The start depends on the listed demonstrations: alone, a demonstration's noisy rollouts start at its own.
  const std::vector<PolicySequence> alone = executeDemos(data, {1}, model, o, 5);
  REQUIRE(alone.size() == 3);
  for (const PolicySequence& s : alone)
    CHECK((s.q.front() - data.demos[1].f.front()).cwiseAbs().maxCoeff() < 1e-9);
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

TEST_CASE("rolloutPolicy applies the policy's action as the controller does (the limited command), from each demonstration's start, deterministically") {
  const auto& [blend, arm, data, model, period] = ReachableArm{};
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
    const std::vector<PolicyRun> runs = rolloutPolicy(data, demos, model, policy);
    REQUIRE(runs.size() == demos.size());
    CHECK(ticks_in_order);
    REQUIRE(starts.size() == demos.size());
    std::size_t saturated = 0;
    for (std::size_t i = 0; i < runs.size(); ++i) {
      const PolicyRun& run = runs[i];
      const PolicyDemo& d = data.demos[static_cast<std::size_t>(run.demo)];
      INFO("demo " << run.demo);
      CHECK(run.demo == demos[i]);
      CHECK(run.movement == d.movement);
      CHECK(starts[i] == d.movement);
      REQUIRE(run.q.size() == d.f.size());
      REQUIRE(run.a.size() == d.f.size() - 1);
      CHECK((run.q.front() - d.f.front()).cwiseAbs().maxCoeff() < 1e-9);
      // An independent replay on a fresh arm: each recorded action is the law on the inputs the
      // controller gives (q, the applied a(t−1), r = clamped f(t+1) − q), and the arm under the
      // limited commands q + a (position limits, one period's reach) visits the recorded states.
      SimData sim(model, JointVector::Zero());
      resetSim(model, sim, d.f.front());
      JointVector a_prev = JointVector::Zero();
      double worst_action = 0.0, worst_q = 0.0;
      for (std::size_t t = 0; t < run.a.size(); ++t) {
        const JointVector r = clampToLimits(arm, d.f[t + 1]) - run.q[t];
        worst_action = std::max(worst_action, (run.a[t] - law(push, d.movement, run.q[t], a_prev, r)).cwiseAbs().maxCoeff());
        const JointVector c = clampedCommand(arm, period, run.q[t], run.a[t], saturated);
        a_prev = c - run.q[t];
        worst_q = std::max(worst_q, (stepSim(model, sim, c) - run.q[t + 1]).cwiseAbs().maxCoeff());
      }
      CHECK(worst_action == 0.0);
      CHECK(worst_q == 0.0);
      CHECK((run.q.back() - run.q.front()).cwiseAbs().maxCoeff() > 0.02);  // the arm moved
    }
    if (push > 0.0) CHECK(saturated > 0);  // the limits were exercised
  }
  // Deterministic: the same policy gives the same runs.
  const RolloutPolicy mild = [&](int movement, int, const JointVector& q, const JointVector& a_prev,
                                 const JointVector& r) -> JointVector { return law(0.0, movement, q, a_prev, r); };
  const std::vector<PolicyRun> a = rolloutPolicy(data, demos, model, mild);
  const std::vector<PolicyRun> b = rolloutPolicy(data, demos, model, mild);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].q == b[i].q);
    CHECK(a[i].a == b[i].a);
  }
  CHECK_THROWS_WITH_AS(rolloutPolicy(data, {99}, model, mild), doctest::Contains("out of range"), UserError);
  CHECK_THROWS_WITH_AS(rolloutPolicy(data, demos, model, RolloutPolicy{}), doctest::Contains("no policy"), UserError);
}

TEST_CASE("rolloutPolicy holds the arm on a non-finite action: NaN acts as the zero action, the arm stays at its start") {
  const auto& [blend, arm, data, model, period] = ReachableArm{};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const RolloutPolicy none = [](int, int, const JointVector&, const JointVector&, const JointVector&) -> JointVector {
    return JointVector::Zero();
  };
  const RolloutPolicy broken = [nan](int, int, const JointVector&, const JointVector&, const JointVector&) -> JointVector {
    JointVector a = JointVector::Constant(0.05);
    a[3] = nan;
    return a;
  };
  const std::vector<int> demos = {0, 4};
  const std::vector<PolicyRun> held = rolloutPolicy(data, demos, model, broken);
  const std::vector<PolicyRun> zero = rolloutPolicy(data, demos, model, none);
  for (std::size_t i = 0; i < held.size(); ++i) {
    CHECK(held[i].q == zero[i].q);  // to the last bit
    for (const JointVector& a : held[i].a) CHECK(a == JointVector::Zero());
    double drift = 0.0;
    for (const JointVector& q : held[i].q) drift = std::max(drift, (q - held[i].q.front()).cwiseAbs().maxCoeff());
    MESSAGE("demo " << held[i].demo << ": held within " << drift << " rad of its start over " << held[i].q.size() << " ticks");
    CHECK(drift < 1e-3);
  }
  // A policy that moves does move the arm (the comparison above is not of two idle runs by design).
  const RolloutPolicy moving = [](int, int, const JointVector&, const JointVector&, const JointVector&) -> JointVector {
    return JointVector::Constant(0.02);
  };
  CHECK((rolloutPolicy(data, {0}, model, moving).front().q.back() - held.front().q.front()).cwiseAbs().maxCoeff() > 0.1);
}
