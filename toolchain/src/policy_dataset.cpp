#include "nao/tools/policy_dataset.hpp"

#include "nao/text_guard.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/csv.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

// splitmix64 (Steele, Lea, Flood 2014): a tiny seeded generator whose output is the same on
// every platform and standard library (std distributions are implementation-defined).
class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  /// Uniform in 0..n-1 without modulo bias (rejection of the incomplete last block).
  std::uint64_t below(std::uint64_t n) {
    const std::uint64_t threshold = (0 - n) % n;
    for (;;) {
      const std::uint64_t r = next();
      if (r >= threshold) return r % n;
    }
  }

 private:
  std::uint64_t state_;
};

std::string movementOf(const std::string& demo_name) {
  const auto cut = demo_name.rfind('_');
  if (cut == std::string::npos || cut == 0 || cut + 1 == demo_name.size()) return {};
  return demo_name.substr(0, cut);
}

bool finite(const JointVector& v) { return v.allFinite(); }

std::string shortNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// Canonical little-endian byte form for the fingerprint.
struct ByteSink {
  std::vector<std::uint8_t> bytes;
  void u64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) bytes.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void f64(double v) {
    std::uint64_t u = 0;
    std::memcpy(&u, &v, sizeof u);
    u64(u);
  }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes.insert(bytes.end(), s.begin(), s.end());
  }
};

std::uint64_t fnv1a(const std::vector<std::uint8_t>& bytes) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (std::uint8_t b : bytes) {
    h ^= b;
    h *= 0x100000001b3ull;
  }
  return h;
}

std::map<std::string, std::vector<JointVector>> readCentroids(const fs::path& path, std::string& retarget_json) {
  std::ifstream in(path);
  if (!in) throw UserError("cannot open " + path.string() + " (run nao_toolchain cluster first)");
  std::ostringstream text;
  text << in.rdbuf();
  // "retarget" is dumped back into model.bin: bound the nesting before nlohmann sees it.
  if (const std::string problem = jsonShapeProblem(text.str()); !problem.empty())
    throw UserError(path.string() + ": not valid centroids JSON: the text " + problem);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text.str());
  } catch (const nlohmann::json::exception& e) {
    throw UserError(path.string() + ": not valid JSON: " + e.what());
  }
  const std::string where = path.string() + ": ";
  if (!j.is_object() || !j.contains("movements") || !j["movements"].is_object() || j["movements"].empty())
    throw UserError(where + "expected an object with a non-empty \"movements\" object");
  std::map<std::string, std::vector<JointVector>> out;
  for (const auto& [name, m] : j["movements"].items()) {
    const std::string at = where + "movements/" + name + "/centroids";
    if (!m.is_object() || !m.contains("centroids") || !m["centroids"].is_array() || m["centroids"].empty())
      throw UserError(at + " is missing or not a non-empty array");
    std::vector<JointVector>& cs = out[name];
    for (std::size_t c = 0; c < m["centroids"].size(); ++c) {
      const auto& row = m["centroids"][c];
      if (!row.is_array() || row.size() != static_cast<std::size_t>(kNumJoints))
        throw UserError(at + "/" + std::to_string(c) + " is not an array of " + std::to_string(kNumJoints) +
                        " numbers");
      JointVector v;
      for (int k = 0; k < kNumJoints; ++k) {
        const auto& x = row[static_cast<std::size_t>(k)];
        if (!x.is_number() || !std::isfinite(x.get<double>()))
          throw UserError(at + "/" + std::to_string(c) + "/" + std::to_string(k) + " is not a finite number");
        v[k] = x.get<double>();
      }
      cs.push_back(v);
    }
  }
  // How the clustered reference was retargeted (cluster writes it); kept verbatim for model.bin.
  retarget_json.clear();
  if (j.contains("retarget")) {
    const auto& r = j["retarget"];
    if (!r.is_object() || !r.contains("priority") || !r["priority"].is_string())
      throw UserError(where + "\"retarget\" is not an object with a \"priority\" string");
    retarget_json = r.dump();
  }
  return out;
}

PolicyDemo readFeatures(const fs::path& path, int clusters) {
  CsvReader csv(path.string(), "features CSV");
  const std::size_t c_t = csv.column("t_s"), c_label = csv.column("label");
  std::size_t c_measured = 0;
  bool has_measured = false;
  try {
    c_measured = csv.column("measured");
    has_measured = true;
  } catch (const UserError&) {
    // Old format (before the measured column): every sample counts as measured.
  }
  std::size_t c_f[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j) c_f[j] = csv.column("f_" + std::to_string(j));

  PolicyDemo demo;
  demo.name = path.parent_path().filename().string();
  while (csv.next()) {
    const double t = csv.number(c_t);
    if (!demo.t_s.empty() && !(t > demo.t_s.back()))
      throw UserError(csv.where() + ": t_s " + shortNumber(t) + " does not increase");
    const double label = csv.number(c_label);
    if (label != std::floor(label) || label < 0 || label >= clusters)
      throw UserError(csv.where() + ": label " + shortNumber(label) + " is not a centroid index 0.." +
                      std::to_string(clusters - 1));
    double measured = 1.0;
    if (has_measured) {
      measured = csv.number(c_measured);
      if (measured != 0.0 && measured != 1.0)
        throw UserError(csv.where() + ": measured is " + shortNumber(measured) + ", expected 0 or 1");
    }
    JointVector f;
    for (int j = 0; j < kNumJoints; ++j) f[j] = csv.number(c_f[j]);
    demo.t_s.push_back(t);
    demo.label.push_back(static_cast<int>(label));
    demo.measured.push_back(static_cast<std::uint8_t>(measured));
    demo.f.push_back(f);
  }
  if (demo.f.size() < 2)
    throw UserError(path.string() + ": " + std::to_string(demo.f.size()) +
                    " samples, a demonstration needs at least 2");
  return demo;
}

}  // namespace

PolicyData loadPolicyData(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw UserError(dir + ": not a directory");
  std::string retarget_json;
  const std::map<std::string, std::vector<JointVector>> centroids =
      readCentroids(fs::path(dir) / "centroids.json", retarget_json);
  const int clusters = static_cast<int>(centroids.begin()->second.size());

  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.is_directory() && fs::exists(entry.path() / "features.csv")) files.push_back(entry.path() / "features.csv");
  std::sort(files.begin(), files.end());
  if (files.empty())
    throw UserError(dir + ": no <movement>_<index>/features.csv found (run nao_toolchain cluster first)");

  std::vector<PolicyDemo> demos;
  for (const fs::path& file : files) {
    const std::string name = file.parent_path().filename().string();
    const std::string movement = movementOf(name);
    if (movement.empty()) throw UserError(file.parent_path().string() + ": directory name is not <movement>_<index>");
    if (centroids.count(movement) == 0)
      throw UserError(file.string() + ": movement '" + movement + "' has no centroids in " +
                      (fs::path(dir) / "centroids.json").string());
    demos.push_back(readFeatures(file, clusters));
  }
  try {
    PolicyData data = makePolicyData(centroids, std::move(demos));
    data.retarget_json = retarget_json;
    return data;
  } catch (const UserError& e) {
    throw UserError(dir + ": " + e.what());
  }
}

PolicyData makePolicyData(const std::map<std::string, std::vector<JointVector>>& centroids,
                          std::vector<PolicyDemo> demos) {
  if (centroids.empty()) throw UserError("no movements with centroids");
  PolicyData data;
  const std::size_t k = centroids.begin()->second.size();
  for (const auto& [name, cs] : centroids) {
    if (cs.empty() || cs.size() != k)
      throw UserError("movement '" + name + "' has " + std::to_string(cs.size()) + " centroids, expected " +
                      std::to_string(k) + " like the first movement (and at least 1)");
    for (const JointVector& c : cs)
      if (!finite(c)) throw UserError("movement '" + name + "' has a non-finite centroid");
    data.movement_names.push_back(name);
    data.centroids.push_back(cs);
  }

  std::sort(demos.begin(), demos.end(), [](const PolicyDemo& a, const PolicyDemo& b) { return a.name < b.name; });
  for (std::size_t i = 0; i < demos.size(); ++i) {
    PolicyDemo& d = demos[i];
    if (i > 0 && demos[i - 1].name == d.name) throw UserError("demonstration '" + d.name + "' appears twice");
    const std::string movement = movementOf(d.name);
    const auto it = std::find(data.movement_names.begin(), data.movement_names.end(), movement);
    if (movement.empty() || it == data.movement_names.end())
      throw UserError("demonstration '" + d.name + "' is not <movement>_<index> of a movement with centroids");
    d.movement = static_cast<int>(it - data.movement_names.begin());
    const std::size_t n = d.f.size();
    if (n < 2) throw UserError("demonstration '" + d.name + "' has " + std::to_string(n) + " samples, needs at least 2");
    if (d.measured.empty()) d.measured.assign(n, 1);
    if (d.t_s.size() != n || d.label.size() != n || d.measured.size() != n)
      throw UserError("demonstration '" + d.name + "': t_s, label, measured and f differ in length");
    for (std::size_t t = 0; t < n; ++t) {
      const std::string at = "demonstration '" + d.name + "' sample " + std::to_string(t) + ": ";
      if (!std::isfinite(d.t_s[t]) || !finite(d.f[t])) throw UserError(at + "non-finite value");
      if (t > 0 && !(d.t_s[t] > d.t_s[t - 1])) throw UserError(at + "t_s does not increase");
      if (d.label[t] < 0 || static_cast<std::size_t>(d.label[t]) >= k)
        throw UserError(at + "label " + std::to_string(d.label[t]) + " is outside 0.." + std::to_string(k - 1));
      if (d.measured[t] > 1) throw UserError(at + "measured flag is not 0 or 1");
    }
  }
  data.demos = std::move(demos);
  return data;
}

std::vector<PolicySample> buildSamples(const PolicyData& data, int demo, int max_steps) {
  const PolicyDemo& d = data.demos.at(static_cast<std::size_t>(demo));
  const std::vector<JointVector>& centroids = data.centroids.at(static_cast<std::size_t>(d.movement));
  std::vector<PolicySample> out;
  out.reserve(d.f.size() - 1);
  for (std::size_t t = 0; t + 1 < d.f.size(); ++t) {
    PolicySample s;
    s.q = d.f[t];
    s.a_prev = t == 0 ? JointVector::Zero().eval() : (d.f[t] - d.f[t - 1]).eval();
    s.r = centroids[static_cast<std::size_t>(d.label[t])];
    s.a = d.f[t + 1] - d.f[t];
    s.movement = d.movement;
    s.step = static_cast<int>(std::min<std::size_t>(t, static_cast<std::size_t>(max_steps - 1)));
    s.demo = demo;
    out.push_back(s);
  }
  return out;
}

std::vector<PolicySample> buildSamples(const PolicyData& data, const std::vector<int>& demos, int max_steps) {
  std::vector<PolicySample> out;
  for (int d : demos) {
    const std::vector<PolicySample> s = buildSamples(data, d, max_steps);
    out.insert(out.end(), s.begin(), s.end());
  }
  return out;
}

namespace {

// The expert of ExecutionOptions: the command in [lo, hi] for which the arm, from the state in
// `snap`, ends the tick nearest `target`. Per-joint secant steps on the end-of-tick angle (the
// servo moves each joint mostly on its own; the iterations absorb the coupling); returns the
// best command tried. Leaves `sim` in the state of `snap`.
JointVector expertCommand(const SimModel& model, SimData& sim, const SimSnapshot& snap, const JointVector& target,
                          const JointVector& lo, const JointVector& hi, const ExecutionOptions& o, double& miss) {
  const auto clampTo = [&](JointVector c) {
    for (int j = 0; j < kNumJoints; ++j) c[j] = std::clamp(c[j], lo[j], hi[j]);
    return c;
  };
  const auto endOf = [&](const JointVector& c) {
    restoreSim(sim, snap);
    return JointVector(stepSim(model, sim, c));
  };
  JointVector c_prev = clampTo(target);
  JointVector e_prev = target - endOf(c_prev);
  JointVector best = c_prev;
  double best_miss = e_prev.cwiseAbs().maxCoeff();
  // First step: the first-order servo inversion.
  const double first_gain = servoStepGain(model.params);
  JointVector c = clampTo(c_prev + first_gain * e_prev);
  for (int it = 0; it < o.expert_iterations && best_miss > o.expert_tol_rad; ++it) {
    const JointVector e = target - endOf(c);
    const double m = e.cwiseAbs().maxCoeff();
    if (m < best_miss) {
      best_miss = m;
      best = c;
    }
    JointVector next = c;
    for (int j = 0; j < kNumJoints; ++j) {
      const double de = e_prev[j] - e[j], dc = c[j] - c_prev[j];
      // Secant on e(c) = target − q_end(c); fall back to the first-order gain when flat.
      const double slope = std::abs(de) > 1e-12 && std::abs(dc) > 1e-12 ? dc / de : first_gain;
      next[j] = c[j] + std::clamp(slope, 0.5, 4.0) * e[j];
    }
    c_prev = c;
    e_prev = e;
    c = clampTo(next);
  }
  restoreSim(sim, snap);
  miss = best_miss;
  return best;
}

}  // namespace

namespace {

// The controller's per-tick command bounds at q: the position limits and one period's reach.
void commandBounds(const SimModel& sim_model, const JointVector& q, JointVector& lo, JointVector& hi) {
  const ArmModel& arm = sim_model.arm;
  const double period = sim_model.params.dt_s * sim_model.params.substeps_per_tick;
  for (int j = 0; j < kNumJoints; ++j) {
    const double step = arm.v_max[j] * period;
    lo[j] = std::max(arm.q_min[j], q[j] - step);
    hi[j] = std::min(arm.q_max[j], q[j] + step);
    if (lo[j] > hi[j]) std::swap(lo[j], hi[j]);
  }
}

// A tick's inputs appended to `s`: q(t), a(t−1) and r. The reference input r is how far the
// tick's feature-extracted target f(t+1) (computed online by the controller from the snapped
// key poses: controller.hpp, kFeatureBlendPole) is from the measured q(t). As a difference, not
// as f(t+1) itself: in normalised units the label needs r − q to ~1e-3 of the angles' spread,
// which the net learnt only slowly (measured).
void recordInputs(const JointVector& q, const JointVector& a_prev, const JointVector& target, PolicySequence& s) {
  s.q.push_back(q);
  s.a_prev.push_back(a_prev);
  s.r.push_back(target - q);
}

// One tick of a rollout from the arm's present state (q measured, `a_prev` applied last tick):
// the controller's per-tick command bounds [lo, hi], the expert's command toward the clamped
// f(t+1) from a snapshot (sim is left in the tick's start state), and the tick's inputs and
// label appended to `s`. Returns the expert's command; `miss` is its end-of-tick miss.
// `clock_target` is the tick's clamped f(t+1) (the reference input r); the expert aims at
// `label_target` (the same, except for DAgger's aligned labels).
JointVector labelTick(const JointVector& clock_target, const JointVector& label_target, const JointVector& q,
                      const JointVector& a_prev, const SimModel& sim_model, SimData& sim, SimSnapshot& snap,
                      const ExecutionOptions& o, PolicySequence& s, JointVector& lo, JointVector& hi, double& miss) {
  commandBounds(sim_model, q, lo, hi);
  captureSim(sim, snap);
  const JointVector c = expertCommand(sim_model, sim, snap, label_target, lo, hi, o, miss);
  recordInputs(q, a_prev, clock_target, s);
  s.a.push_back(c - q);
  return c;
}

// How much a velocity mismatch counts against a position mismatch in the alignment: a per-tick
// velocity error weighs as that error carried on for this many ticks. It tells the outward
// from the return stroke through the same pose.
constexpr double kAlignVelocityTicks = 2.0;

// DAgger's aligned point (ExecutionOptions::dagger_align_band): among the pool's clean
// executions of `movement`, the point (d, k) with |k − t| <= band and a successor that minimises
// |q − F_d(k)|² + (kAlignVelocityTicks·|v − (F_d(k) − F_d(k−1))|)² (F: f clamped to the limits,
// F_d(−1) = F_d(0): at rest; v = q(t) − q(t−1)); the first in pool and tick order on ties.
// `seq` is null when no execution is long enough for the band.
struct AlignedPoint {
  const PolicySequence* seq = nullptr;
  std::size_t k = 0;
};

AlignedPoint alignState(const PolicyData& data, const std::vector<PolicySequence>& pool, int movement, std::size_t t,
                        const JointVector& q, const JointVector& v, const ArmModel& arm, int band_ticks) {
  const std::size_t band = static_cast<std::size_t>(band_ticks);
  double best = std::numeric_limits<double>::infinity();
  AlignedPoint p;
  for (const PolicySequence& seq : pool) {
    if (seq.rollout != 0 || seq.movement != movement || seq.ticks() == 0) continue;
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(seq.demo)];
    const std::size_t first = t > band ? t - band : 0, last = std::min(t + band, seq.ticks() - 1);
    if (first > last) continue;
    JointVector before = clampToLimits(arm, demo.f[first > 0 ? first - 1 : 0]);
    for (std::size_t k = first; k <= last; ++k) {
      const JointVector at = clampToLimits(arm, demo.f[k]);
      const double cost = (q - at).squaredNorm() + (kAlignVelocityTicks * (v - (at - before))).squaredNorm();
      if (cost < best) {
        best = cost;
        p.seq = &seq;
        p.k = k;
      }
      before = at;
    }
  }
  return p;
}

// Rollout k of demonstration d (see executeDemos), on `sim` (any state; reset here).
PolicySequence executeRollout(const PolicyData& data, int d, int k, const SimModel& sim_model, SimData& sim,
                              const ExecutionOptions& o, std::uint64_t seed) {
  const PolicyDemo& demo = data.demos.at(static_cast<std::size_t>(d));
  PolicySequence s;
  s.demo = d;
  s.movement = demo.movement;
  s.rollout = k;
  const double sd = k == 0 ? 0.0 : o.noise_std_rad[static_cast<std::size_t>(k - 1) % o.noise_std_rad.size()];
  SplitMix64 rng(seed ^ (0x9e3779b97f4a7c15ull * static_cast<std::uint64_t>(d + 1)) ^
                 (0xc2b2ae3d27d4eb4full * static_cast<std::uint64_t>(k + 1)));
  const auto uniform = [&rng] { return (static_cast<double>(rng.next() >> 11) + 0.5) * 0x1.0p-53; };
  const auto normal = [&] {
    const double u1 = uniform();  // two statements: the order of draws is fixed
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  };
  SimSnapshot snap;
  resetSim(sim_model, sim, demo.f.front());
  JointVector q = sim.q, a_prev = JointVector::Zero(), noise = JointVector::Zero();
  const double innovation = sd * std::sqrt(1.0 - o.noise_corr * o.noise_corr);
  for (std::size_t t = 0; t + 1 < demo.f.size(); ++t) {
    JointVector lo, hi;
    double miss = 0.0;
    const JointVector target = clampToLimits(sim_model.arm, demo.f[t + 1]);
    const JointVector c = labelTick(target, target, q, a_prev, sim_model, sim, snap, o, s, lo, hi, miss);
    if (k == 0) s.worst_miss_rad = std::max(s.worst_miss_rad, miss);
    JointVector c_exec = c;
    if (k > 0) {
      for (int j = 0; j < kNumJoints; ++j) noise[j] = o.noise_corr * noise[j] + innovation * normal();
      c_exec += noise;
      for (int j = 0; j < kNumJoints; ++j) c_exec[j] = std::clamp(c_exec[j], lo[j], hi[j]);
    }
    a_prev = c_exec - q;
    q = stepSim(sim_model, sim, c_exec);
  }
  return s;
}

// The policy's rollout of demonstration d (see executePolicyRollouts), on `sim` (reset here).
PolicySequence executePolicyRollout(const PolicyData& data, int d, const SimModel& sim_model, SimData& sim,
                                    const ExecutionOptions& o, const RolloutPolicy& policy, int round, bool labels,
                                    const std::vector<PolicySequence>& align_pool) {
  const ArmModel& arm = sim_model.arm;
  const PolicyDemo& demo = data.demos.at(static_cast<std::size_t>(d));
  PolicySequence s;
  s.demo = d;
  s.movement = demo.movement;
  s.rollout = -round;
  // β-mixing: the expert's ticks keep the round's states near the demonstration while the
  // policy's ticks still show where its own errors lead. Its own stream per (demo, round).
  const double beta = round >= 1 ? std::pow(o.dagger_beta, round) : 0.0;
  SplitMix64 rng(0x5851f42d4c957f2dull ^ (0x9e3779b97f4a7c15ull * static_cast<std::uint64_t>(d + 1)) ^
                 (0xc2b2ae3d27d4eb4full * static_cast<std::uint64_t>(round + 1)));
  SimSnapshot snap;
  resetSim(sim_model, sim, demo.f.front());
  JointVector q = sim.q, q_last = sim.q, a_prev = JointVector::Zero();
  const bool bounded = round >= 1 && o.dagger_max_drift_rad > 0.0;
  const bool aligned = round >= 1 && labels && o.dagger_align_band > 0;
  bool cut = false;
  for (std::size_t t = 0; t + 1 < demo.f.size(); ++t) {
    const double drift = (q - clampToLimits(arm, demo.f[t])).cwiseAbs().maxCoeff();
    s.drift_rad = std::max(s.drift_rad, drift);
    const JointVector clock_target = clampToLimits(arm, demo.f[t + 1]);
    JointVector label_target = clock_target;
    double off = drift;  // what the drift bound measures: from the clock's point or the aligned one
    AlignedPoint p;
    if (aligned) {
      p = alignState(data, align_pool, demo.movement, t, q, q - q_last, arm, o.dagger_align_band);
      if (p.seq != nullptr) {
        const std::vector<JointVector>& f = data.demos[static_cast<std::size_t>(p.seq->demo)].f;
        const JointVector at = clampToLimits(arm, f[p.k]);
        off = (q - at).cwiseAbs().maxCoeff();
        label_target = clampToLimits(arm, JointVector(clampToLimits(arm, f[p.k + 1]) + (1.0 - o.dagger_return) * (q - at)));
      }  // else (no execution long enough for the band): the clock's target
    }
    if (bounded && off > o.dagger_max_drift_rad) {
      cut = true;
      break;
    }
    JointVector lo, hi, expert = JointVector::Zero();
    const bool command_label =
        labels && p.seq != nullptr && o.dagger_align_label == ExecutionOptions::AlignLabel::kCommand;
    if (labels && !command_label) {
      double miss = 0.0;
      expert = labelTick(clock_target, label_target, q, a_prev, sim_model, sim, snap, o, s, lo, hi, miss);
      s.worst_miss_rad = std::max(s.worst_miss_rad, miss);
    } else {
      // No expert search. It leaves the arm as restoreSim sets it, which is not bit for bit the
      // state it captured (ODE renormalises the quaternions): the same round trip keeps q identical.
      commandBounds(sim_model, q, lo, hi);
      captureSim(sim, snap);
      restoreSim(sim, snap);
      recordInputs(q, a_prev, clock_target, s);
      if (command_label) {
        // The clean execution's command at the aligned point, as the controller would bound it here.
        expert = p.seq->q[p.k] + p.seq->a[p.k];
        for (int j = 0; j < kNumJoints; ++j) expert[j] = std::clamp(expert[j], lo[j], hi[j]);
        s.a.push_back(expert - q);
      }
    }
    // The policy runs every tick (its streaming cache must see each one), even when the expert acts.
    JointVector a = policy(demo.movement, static_cast<int>(t), q, a_prev, s.r.back());
    if (!a.allFinite()) a.setZero();  // as the controller does (kFaultPolicyNonFinite)
    // The controller's command: q + a inside the position limits and one period's reach; or
    // the expert's own command (inside them already; q + (c − q) could round away from c).
    JointVector c_exec = q + a;
    for (int j = 0; j < kNumJoints; ++j) c_exec[j] = std::clamp(c_exec[j], lo[j], hi[j]);
    if (labels && beta > 0.0 && static_cast<double>(rng.next() >> 11) * 0x1.0p-53 < beta) {
      c_exec = expert;
      ++s.expert_ticks;
    }
    a_prev = c_exec - q;
    q_last = q;
    q = stepSim(sim_model, sim, c_exec);
  }
  if (!cut) s.drift_rad = std::max(s.drift_rad, (q - clampToLimits(arm, demo.f.back())).cwiseAbs().maxCoeff());
  return s;
}

}  // namespace

namespace {

void checkExecution(const PolicyData& data, const std::vector<int>& demos, const ExecutionOptions& o) {
  if (o.noisy_rollouts < 0) throw UserError("execution: noisy_rollouts must not be negative");
  if (o.noisy_rollouts > 0 && o.noise_std_rad.empty()) throw UserError("execution: no noise standard deviation given");
  for (double sd : o.noise_std_rad)
    if (!(sd >= 0.0)) throw UserError("execution: noise standard deviation " + std::to_string(sd) + " is negative");
  if (!(o.noise_corr >= 0.0 && o.noise_corr < 1.0)) throw UserError("execution: noise_corr must be in [0, 1)");
  if (o.expert_iterations < 1) throw UserError("execution: expert_iterations must be at least 1");
  if (o.threads < 1) throw UserError("execution: threads must be at least 1");
  if (!(o.dagger_beta >= 0.0 && o.dagger_beta <= 1.0)) throw UserError("execution: dagger_beta must be in [0, 1]");
  if (!(o.dagger_max_drift_rad >= 0.0)) throw UserError("execution: dagger_max_drift_rad must not be negative");
  if (o.dagger_align_band < 0) throw UserError("execution: dagger_align_band must not be negative");
  if (!(o.dagger_return > 0.0 && o.dagger_return <= 1.0)) throw UserError("execution: dagger_return must be in (0, 1]");
  for (int d : demos)
    if (d < 0 || static_cast<std::size_t>(d) >= data.demos.size())
      throw UserError("execution: demonstration index " + std::to_string(d) + " is out of range");
}

}  // namespace

std::vector<PolicySequence> executeDemos(const PolicyData& data, const std::vector<int>& demos,
                                         const SimModel& sim_model, const ExecutionOptions& o, std::uint64_t seed,
                                         std::ostream* progress) {
  checkExecution(data, demos, o);
  const std::size_t per_demo = static_cast<std::size_t>(1 + o.noisy_rollouts);
  const std::size_t total = demos.size() * per_demo;
  std::vector<PolicySequence> out(total);
  // Rollouts are independent (own seed stream, reset arm): threads take them in turn and each
  // result goes to its own slot, so the output does not depend on the thread count.
  std::atomic<std::size_t> next{0}, done{0};
  std::mutex report;
  std::size_t reported = 0;
  std::exception_ptr failure;
  const auto work = [&] {
    try {
      SimData sim(sim_model, JointVector::Zero());  // ODE data per thread: built on this thread
      for (std::size_t i = next++; i < total; i = next++) {
        out[i] = executeRollout(data, demos[i / per_demo], static_cast<int>(i % per_demo), sim_model, sim, o, seed);
        const std::size_t n = ++done;
        if (progress) {
          const std::lock_guard<std::mutex> lock(report);
          if (n * 10 / total > reported) {
            reported = n * 10 / total;
            *progress << "executed " << n << "/" << total << " rollouts" << std::endl;
          }
        }
      }
    } catch (...) {
      const std::lock_guard<std::mutex> lock(report);
      if (!failure) failure = std::current_exception();
      next = total;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < o.threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
  return out;
}

std::vector<PolicySequence> executePolicyRollouts(const PolicyData& data, const std::vector<int>& demos,
                                                  const SimModel& sim_model, const ExecutionOptions& o,
                                                  const RolloutPolicy& policy, int round, bool labels,
                                                  const std::vector<PolicySequence>& align_pool) {
  checkExecution(data, demos, o);
  if (!policy) throw UserError("execution: no policy to roll out");
  if (!labels && round >= 1 && o.dagger_beta > 0.0) throw UserError("execution: beta-mixing needs the expert's labels");
  if (labels && round >= 1 && o.dagger_align_band > 0) {
    std::vector<int> clean;
    for (const PolicySequence& p : align_pool)
      if (p.rollout == 0) clean.push_back(p.demo);
    if (clean.empty()) throw UserError("execution: aligned DAgger labels need clean executions to align to");
    checkExecution(data, clean, o);
    for (const PolicySequence& p : align_pool)
      if (p.rollout == 0 && (p.q.size() != p.ticks() || p.movement != data.demos[static_cast<std::size_t>(p.demo)].movement ||
                             p.ticks() + 1 > data.demos[static_cast<std::size_t>(p.demo)].f.size()))
        throw UserError("execution: an alignment sequence does not fit its demonstration");
  }
  std::vector<PolicySequence> out;
  out.reserve(demos.size());
  SimData sim(sim_model, JointVector::Zero());
  for (int d : demos) out.push_back(executePolicyRollout(data, d, sim_model, sim, o, policy, round, labels, align_pool));
  return out;
}

NormStats normStats(const std::vector<PolicySequence>& sequences) {
  std::vector<PolicySample> flat;
  for (const PolicySequence& s : sequences)
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      PolicySample x;
      x.q = s.q[t];
      x.a_prev = s.a_prev[t];
      x.r = s.r[t];
      x.a = s.a[t];
      flat.push_back(x);
    }
  return normStats(flat);
}

Baselines baselines(const std::vector<PolicySequence>& sequences) {
  Baselines b;
  std::size_t n = 0;
  for (const PolicySequence& s : sequences)
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      b.zero_action += s.a[t].squaredNorm();
      b.repeat_last += (s.a[t] - s.a_prev[t]).squaredNorm();
      ++n;
    }
  if (n == 0) return b;
  const double count = static_cast<double>(n) * kNumJoints;
  b.zero_action /= count;
  b.repeat_last /= count;
  return b;
}

std::size_t tickCount(const std::vector<PolicySequence>& sequences) {
  std::size_t n = 0;
  for (const PolicySequence& s : sequences) n += s.ticks();
  return n;
}

PolicySplit splitByDemonstration(const PolicyData& data, double val_fraction, std::uint64_t seed) {
  if (!(val_fraction >= 0.0 && val_fraction < 1.0))
    throw UserError("validation fraction " + std::to_string(val_fraction) + " is not in [0, 1)");
  PolicySplit split;
  for (int m = 0; m < data.movements(); ++m) {
    std::vector<int> demos;  // name order
    for (std::size_t i = 0; i < data.demos.size(); ++i)
      if (data.demos[i].movement == m) demos.push_back(static_cast<int>(i));
    // Fisher-Yates, one stream per movement: adding a movement leaves the others' splits alone.
    SplitMix64 rng(seed ^ (0xd1b54a32d192ed03ull * static_cast<std::uint64_t>(m + 1)));
    for (std::size_t i = demos.size(); i > 1; --i) std::swap(demos[i - 1], demos[rng.below(i)]);
    const std::size_t n = demos.size();
    std::size_t n_val = static_cast<std::size_t>(std::lround(val_fraction * static_cast<double>(n)));
    if (n >= 2 && val_fraction > 0.0) n_val = std::clamp<std::size_t>(n_val, 1, n - 1);
    if (n < 2) n_val = 0;
    split.train.insert(split.train.end(), demos.begin(), demos.end() - static_cast<std::ptrdiff_t>(n_val));
    split.val.insert(split.val.end(), demos.end() - static_cast<std::ptrdiff_t>(n_val), demos.end());
  }
  std::sort(split.train.begin(), split.train.end());
  std::sort(split.val.begin(), split.val.end());
  return split;
}

std::vector<std::size_t> shuffledIndices(std::size_t n, std::uint64_t seed) {
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  SplitMix64 rng(seed);
  for (std::size_t i = n; i > 1; --i) std::swap(order[i - 1], order[rng.below(i)]);
  return order;
}

NormStats normStats(const std::vector<PolicySample>& samples) {
  if (samples.empty()) throw UserError("normalisation statistics need at least one training sample");
  const double n = static_cast<double>(samples.size());
  JointVector sum_q = JointVector::Zero(), sum_a = JointVector::Zero(), sum_r = JointVector::Zero();
  for (const PolicySample& s : samples) {
    sum_q += s.q;
    sum_a += s.a;
    sum_r += s.r;
  }
  NormStats st;
  st.q_mean = sum_q / n;
  st.a_mean = sum_a / n;
  st.r_mean = sum_r / n;
  // Two-pass variance: no cancellation for the tiny action values.
  JointVector var_q = JointVector::Zero(), var_a = JointVector::Zero(), var_r = JointVector::Zero();
  for (const PolicySample& s : samples) {
    var_q += (s.q - st.q_mean).cwiseAbs2();
    var_a += (s.a - st.a_mean).cwiseAbs2();
    var_r += (s.r - st.r_mean).cwiseAbs2();
  }
  const auto floored = [n](const JointVector& var) -> JointVector {
    return (var / n).cwiseSqrt().cwiseMax(kMinStd);
  };
  st.q_std = floored(var_q);
  st.a_std = floored(var_a);
  st.r_std = floored(var_r);
  return st;
}

Baselines baselines(const std::vector<PolicySample>& samples) {
  Baselines b;
  if (samples.empty()) return b;
  for (const PolicySample& s : samples) {
    b.zero_action += s.a.squaredNorm();
    b.repeat_last += (s.a - s.a_prev).squaredNorm();
  }
  const double count = static_cast<double>(samples.size()) * kNumJoints;
  b.zero_action /= count;
  b.repeat_last /= count;
  return b;
}

std::uint64_t dataFingerprint(const PolicyData& data) {
  ByteSink sink;
  sink.u32(static_cast<std::uint32_t>(data.movements()));
  sink.u32(static_cast<std::uint32_t>(data.clusters()));
  for (int m = 0; m < data.movements(); ++m) {
    sink.str(data.movement_names[static_cast<std::size_t>(m)]);
    for (const JointVector& c : data.centroids[static_cast<std::size_t>(m)])
      for (int j = 0; j < kNumJoints; ++j) sink.f64(c[j]);
  }
  sink.u32(static_cast<std::uint32_t>(data.demos.size()));
  for (const PolicyDemo& d : data.demos) {
    sink.str(d.name);
    sink.u32(static_cast<std::uint32_t>(d.movement));
    sink.u64(d.f.size());
    for (std::size_t t = 0; t < d.f.size(); ++t) {
      sink.f64(d.t_s[t]);
      sink.u32(static_cast<std::uint32_t>(d.label[t]));
      sink.bytes.push_back(d.measured[t]);
      for (int j = 0; j < kNumJoints; ++j) sink.f64(d.f[t][j]);
    }
  }
  return fnv1a(sink.bytes);
}

std::string hex64(std::uint64_t value) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(value));
  return buf;
}

const char* paceMethodName(PaceMethod method) { return method == PaceMethod::kDtw ? "dtw" : "linear"; }

PaceMethod parsePaceMethod(const std::string& name) {
  if (name == "linear") return PaceMethod::kLinear;
  if (name == "dtw") return PaceMethod::kDtw;
  throw UserError("unknown pace method '" + name + "' (linear or dtw)");
}

namespace {

// f at fractional sample position u (0 <= u <= size − 1), linearly interpolated.
JointVector sampleAt(const std::vector<JointVector>& f, double u) {
  const std::size_t n = f.size();
  if (!(u > 0.0)) return f.front();
  if (u >= static_cast<double>(n - 1)) return f.back();
  const auto i = static_cast<std::size_t>(u);
  const double w = u - static_cast<double>(i);
  return JointVector((1.0 - w) * f[i] + w * f[i + 1]);
}

}  // namespace

std::vector<JointVector> pacedTrajectory(const std::vector<JointVector>& f, int pace_ticks) {
  if (pace_ticks < 2) throw UserError("a canonical pace needs at least 2 samples, not " + std::to_string(pace_ticks));
  const std::size_t n = f.size();
  if (n < 2) return f;
  const std::size_t l = std::min<std::size_t>(static_cast<std::size_t>(pace_ticks), n);
  std::vector<JointVector> out(n, f.back());
  // Sample t of the paced movement is time u = t·(n−1)/(l−1) of the original, in samples.
  for (std::size_t t = 0; t < l; ++t) {
    const std::size_t num = t * (n - 1);
    const std::size_t i = num / (l - 1);
    const double w = static_cast<double>(num % (l - 1)) / static_cast<double>(l - 1);
    out[t] = i + 1 < n ? JointVector((1.0 - w) * f[i] + w * f[i + 1]) : f[n - 1];
  }
  return out;
}

std::optional<std::vector<double>> dtwWarp(const std::vector<JointVector>& f, const std::vector<JointVector>& tmpl) {
  const std::size_t n = f.size(), l = tmpl.size();
  if (n < 2 || l < 2) throw UserError("a time warp needs at least 2 samples on each side");
  // Steps (di, dk) = (1,1), (2,1), (1,2): the warp's slope stays in [1/2, 2], so no stretch of f
  // is sped up more than twice (an unconstrained path can skip a whole loop in one template
  // sample: steps of ~1 rad per tick that no servo follows). A step's cost is the cells it passes.
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> cost(n * l), acc(n * l, inf);
  std::vector<std::uint8_t> step(n * l, 0);  // 1: (1,1), 2: (2,1), 3: (1,2)
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t k = 0; k < l; ++k) cost[i * l + k] = (f[i] - tmpl[k]).norm();
  acc[0] = cost[0];
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t k = 0; k < l; ++k) {
      if (i == 0 && k == 0) continue;
      double best = inf;
      std::uint8_t arg = 0;
      if (i >= 1 && k >= 1 && acc[(i - 1) * l + k - 1] < best) best = acc[(i - 1) * l + k - 1], arg = 1;
      if (i >= 2 && k >= 1 && acc[(i - 2) * l + k - 1] + cost[(i - 1) * l + k] < best)
        best = acc[(i - 2) * l + k - 1] + cost[(i - 1) * l + k], arg = 2;
      if (i >= 1 && k >= 2 && acc[(i - 1) * l + k - 2] + cost[i * l + k - 1] < best)
        best = acc[(i - 1) * l + k - 2] + cost[i * l + k - 1], arg = 3;
      if (arg == 0) continue;
      acc[i * l + k] = best + cost[i * l + k];
      step[i * l + k] = arg;
    }
  if (!(acc[n * l - 1] < inf)) return std::nullopt;  // more than twice as long (or short) as the template
  // Back from the end: the position in f of every template sample.
  std::vector<double> raw(l, 0.0), u(l);
  std::size_t i = n - 1, k = l - 1;
  raw[k] = static_cast<double>(i);
  while (i > 0 || k > 0) {
    const std::uint8_t s = step[i * l + k];
    if (s == 3) raw[k - 1] = static_cast<double>(i) - 0.5;
    i -= s == 2 ? 2 : 1;
    k -= s == 3 ? 2 : 1;
    raw[k] = static_cast<double>(i);
  }
  // Steps of slope 1/2, 1 and 2 make a jerky clock; a short average smooths it (slopes stay
  // within [1/2, 2]).
  constexpr std::size_t kHalf = 2;
  for (std::size_t j = 0; j < l; ++j) {
    // Symmetric, narrowing at the ends (a straight warp stays straight).
    const std::size_t h = std::min({kHalf, j, l - 1 - j});
    double sum = 0.0;
    for (std::size_t q = j - h; q <= j + h; ++q) sum += raw[q];
    u[j] = sum / static_cast<double>(2 * h + 1);
  }
  u.front() = 0.0;
  u.back() = static_cast<double>(n - 1);
  for (std::size_t j = 1; j < l; ++j) u[j] = std::min(std::max(u[j], u[j - 1]), static_cast<double>(n - 1));
  return u;
}

namespace {

// f at the pace of tmpl (pacedTrajectory) and, for every paced sample, its position in f.
struct Paced {
  std::vector<JointVector> f;
  std::vector<double> u;
};

Paced pace(const std::vector<JointVector>& f, const std::vector<JointVector>& tmpl, PaceMethod method) {
  const std::size_t n = f.size(), l = tmpl.size();
  if (l < 2) throw UserError("a canonical pace needs a template of at least 2 samples");
  Paced p;
  if (n <= l) {
    p.f = f;
    for (std::size_t t = 0; t < n; ++t) p.u.push_back(static_cast<double>(t));
    return p;
  }
  p.u.assign(n, static_cast<double>(n - 1));  // the hold
  const std::optional<std::vector<double>> w = method == PaceMethod::kDtw ? dtwWarp(f, tmpl) : std::nullopt;
  if (w) {
    std::copy(w->begin(), w->end(), p.u.begin());
    p.f.assign(n, f.back());
    for (std::size_t k = 0; k < l; ++k) p.f[k] = sampleAt(f, p.u[k]);
  } else {  // linear, or no warp within the slope bounds
    p.f = pacedTrajectory(f, static_cast<int>(l));
    for (std::size_t t = 0; t < l; ++t) p.u[t] = static_cast<double>(t * (n - 1)) / static_cast<double>(l - 1);
  }
  return p;
}

}  // namespace

std::vector<JointVector> pacedTrajectory(const std::vector<JointVector>& f, const std::vector<JointVector>& tmpl,
                                         PaceMethod method) {
  return pace(f, tmpl, method).f;
}

std::vector<int> paceTemplates(const PolicyData& data, const std::vector<int>& demos) {
  std::vector<int> tmpl(static_cast<std::size_t>(data.movements()), -1);
  for (int d : demos) {
    const PolicyDemo& demo = data.demos.at(static_cast<std::size_t>(d));
    int& t = tmpl.at(static_cast<std::size_t>(demo.movement));
    if (t < 0 || demo.f.size() < data.demos[static_cast<std::size_t>(t)].f.size()) t = d;
  }
  return tmpl;
}

PolicyData pacedData(const PolicyData& data, const std::vector<int>& templates, PaceMethod method) {
  if (static_cast<int>(templates.size()) != data.movements())
    throw UserError("a canonical pace needs one template per movement (" + std::to_string(data.movements()) + "), not " +
                    std::to_string(templates.size()));
  for (std::size_t m = 0; m < templates.size(); ++m) {
    const int t = templates[m];
    if (t < 0 || static_cast<std::size_t>(t) >= data.demos.size() || data.demos[static_cast<std::size_t>(t)].movement != static_cast<int>(m))
      throw UserError("a canonical pace needs a template demonstration of movement " + data.movement_names[m]);
  }
  PolicyData out = data;
  for (std::size_t di = 0; di < out.demos.size(); ++di) {
    const PolicyDemo& orig = data.demos[di];
    PolicyDemo& d = out.demos[di];
    const Paced p = pace(orig.f, data.demos[static_cast<std::size_t>(templates[static_cast<std::size_t>(d.movement)])].f, method);
    d.f = p.f;
    // The label and measured flag of the original sample nearest each paced one.
    for (std::size_t t = 0; t < p.u.size(); ++t) {
      const auto i = static_cast<std::size_t>(std::lround(p.u[t]));
      d.label[t] = orig.label[i];
      d.measured[t] = orig.measured[i];
    }
  }
  return out;
}

std::vector<std::string> demoNames(const PolicyData& data, const std::vector<int>& demos) {
  std::vector<std::string> names;
  for (int d : demos) names.push_back(data.demos.at(static_cast<std::size_t>(d)).name);
  return names;
}

}  // namespace nao::tools
