#include "nao/tools/policy_dataset.hpp"

#include "nao/text_guard.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/csv.hpp"
#include "nao/tools/splitmix.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
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

// The retargeted reference at the demonstration's first measured sample (retarget.csv's qr_*,
// the same 10 Hz grid as features.csv); f(0) when there is no retarget.csv.
JointVector readStart(const fs::path& path, const PolicyDemo& demo) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return demo.f.front();
  std::size_t first = 0;
  while (first + 1 < demo.measured.size() && demo.measured[first] == 0) ++first;
  const double t0 = demo.t_s[first];
  CsvReader csv(path.string(), "retarget CSV");
  const std::size_t c_t = csv.column("t_s");
  std::size_t c_q[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j) c_q[j] = csv.column("qr_" + std::to_string(j));
  while (csv.next()) {
    if (std::abs(csv.number(c_t) - t0) > 1e-6) continue;
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j) q[j] = csv.number(c_q[j]);
    if (!finite(q)) throw UserError(csv.where() + ": non-finite qr");
    return q;
  }
  throw UserError(path.string() + ": no row at t_s " + shortNumber(t0) + " (the first measured sample of " +
                  (path.parent_path() / "features.csv").string() + ")");
}

}  // namespace

PolicyData fromOwnStarts(const PolicyData& data) {
  PolicyData out = data;
  const KeyPoseBlend blend;
  for (PolicyDemo& d : out.demos) {
    const std::vector<JointVector>& keys = data.centroids[static_cast<std::size_t>(d.movement)];
    JointVector f = d.start, v = JointVector::Zero();
    for (std::size_t t = 0; t < d.f.size(); ++t) {
      d.f[t] = f;
      v = blend.velocity(v, f, keys[static_cast<std::size_t>(d.label[t])]);
      f += v;
    }
  }
  return out;
}

std::vector<ModelWorkspace> demonstratedWorkspace(const PolicyData& data) {
  std::vector<ModelWorkspace> out(data.movement_names.size());
  std::vector<bool> seen(out.size(), false);
  for (const PolicyDemo& d : data.demos)
    for (const JointVector& q : d.f) {
      ModelWorkspace& w = out[static_cast<std::size_t>(d.movement)];
      if (!seen[static_cast<std::size_t>(d.movement)]) {
        w.lo = w.hi = q;
        seen[static_cast<std::size_t>(d.movement)] = true;
      }
      w.lo = w.lo.cwiseMin(q);
      w.hi = w.hi.cwiseMax(q);
    }
  // A demonstration begins at its start, the retargeted first pose: demonstrated too.
  for (const PolicyDemo& d : data.demos) {
    ModelWorkspace& w = out[static_cast<std::size_t>(d.movement)];
    w.lo = w.lo.cwiseMin(d.start);
    w.hi = w.hi.cwiseMax(d.start);
  }
  return out;
}

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
    demos.back().start = readStart(file.parent_path() / "retarget.csv", demos.back());
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
    if (d.start.hasNaN()) d.start = d.f.front();
    if (!finite(d.start)) throw UserError("demonstration '" + d.name + "' has a non-finite start");
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

NormStats normStats(const std::vector<PolicySequence>& sequences) {
  std::size_t count = 0;
  JointVector sum_q = JointVector::Zero(), sum_a = JointVector::Zero(), sum_r = JointVector::Zero();
  for (const PolicySequence& s : sequences)
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      sum_q += s.q[t];
      sum_a += s.a[t];
      sum_r += s.r[t];
      ++count;
    }
  if (count == 0) throw UserError("normalisation statistics need at least one training tick");
  const double n = static_cast<double>(count);
  NormStats st;
  st.q_mean = sum_q / n;
  st.a_mean = sum_a / n;
  st.r_mean = sum_r / n;
  // Two-pass variance: no cancellation for the tiny action values.
  JointVector var_q = JointVector::Zero(), var_a = JointVector::Zero(), var_r = JointVector::Zero();
  for (const PolicySequence& s : sequences)
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      var_q += (s.q[t] - st.q_mean).cwiseAbs2();
      var_a += (s.a[t] - st.a_mean).cwiseAbs2();
      var_r += (s.r[t] - st.r_mean).cwiseAbs2();
    }
  const auto floored = [n](const JointVector& var) -> JointVector { return (var / n).cwiseSqrt().cwiseMax(kMinStd); };
  st.q_std = floored(var_q);
  st.a_std = floored(var_a);
  st.r_std = floored(var_r);
  return st;
}

Baselines baselines(const std::vector<PolicySequence>& sequences, double gain) {
  Baselines b;
  std::size_t n = 0;
  for (const PolicySequence& s : sequences)
    for (std::size_t t = 0; t < s.ticks(); ++t) {
      b.zero_action += s.a[t].squaredNorm();
      b.repeat_last += (s.a[t] - s.a_prev[t]).squaredNorm();
      b.gain_law += (s.a[t] - gain * s.r[t]).squaredNorm();
      ++n;
    }
  if (n == 0) return b;
  const double count = static_cast<double>(n) * kNumJoints;
  b.zero_action /= count;
  b.repeat_last /= count;
  b.gain_law /= count;
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
    for (int j = 0; j < kNumJoints; ++j) sink.f64(d.start[j]);
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

std::vector<std::string> demoNames(const PolicyData& data, const std::vector<int>& demos) {
  std::vector<std::string> names;
  for (int d : demos) names.push_back(data.demos.at(static_cast<std::size_t>(d)).name);
  return names;
}

}  // namespace nao::tools
