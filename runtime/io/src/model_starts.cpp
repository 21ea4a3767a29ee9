// The autonomous starts of model.bin's metadata (nao/model_file.hpp: modelStarts,
// withModelStarts).
#include "model_metadata_json.hpp"
#include "nao/model_file.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace nao {
namespace {

using Json = nlohmann::ordered_json;

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw ModelFileError(origin + ": metadata \"starts\" " + what);
}

}  // namespace

ModelStarts detail::startsFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names, const std::string& origin) {
  ModelStarts starts(movement_names.size());
  if (!j.is_object() || !j.contains("starts")) return starts;
  const Json& s = j["starts"];
  if (!s.is_object()) fail(origin, "is not an object of movements");
  for (auto it = s.begin(); it != s.end(); ++it)
    if (std::find(movement_names.begin(), movement_names.end(), it.key()) == movement_names.end())
      fail(origin, "names '" + it.key() + "', which is not a movement of the model");
  for (std::size_t m = 0; m < movement_names.size(); ++m) {
    const std::string& movement = movement_names[m];
    if (!s.contains(movement)) fail(origin, "has no entry for movement '" + movement + "'");
    const Json& list = s[movement];
    if (!list.is_array()) fail(origin, "of '" + movement + "' is not a list");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const Json& e = list[i];
      const std::string where = "of '" + movement + "', entry " + std::to_string(i) + ", ";
      if (!e.is_object()) fail(origin, where + "is not an object");
      if (!e.contains("name") || !e["name"].is_string() || e["name"].get<std::string>().empty())
        fail(origin, where + "has no name (a non-empty string)");
      if (!e.contains("ticks") || !e["ticks"].is_number_integer() || e["ticks"].get<std::int64_t>() < 1 ||
          e["ticks"].get<std::int64_t>() > kMaxStartTicks)
        fail(origin, where + "has no ticks (an integer in 1.." + std::to_string(kMaxStartTicks) + ")");
      if (!e.contains("q") || !e["q"].is_array() || e["q"].size() != static_cast<std::size_t>(kNumJoints))
        fail(origin, where + "has no q (" + std::to_string(kNumJoints) + " joint angles, rad)");
      ModelStart start;
      start.name = e["name"].get<std::string>();
      start.ticks = e["ticks"].get<std::int64_t>();
      for (int k = 0; k < kNumJoints; ++k) {
        const Json& v = e["q"][static_cast<std::size_t>(k)];
        if (!v.is_number() || !std::isfinite(v.get<double>())) fail(origin, where + "has a q that is not finite numbers");
        start.q[k] = v.get<double>();
      }
      starts[m].push_back(std::move(start));
    }
  }
  return starts;
}

std::string withModelStarts(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                            const ModelStarts& starts) {
  Json j = metadata_json.empty() ? Json::object() : Json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw ModelFileError("the model's metadata is not a JSON object: cannot add \"starts\"");
  if (starts.size() != movement_names.size())
    throw ModelFileError("starts for " + std::to_string(starts.size()) + " movements, the model has " +
                         std::to_string(movement_names.size()));
  Json s = Json::object();
  for (std::size_t m = 0; m < movement_names.size(); ++m) {
    Json list = Json::array();
    for (const ModelStart& start : starts[m]) {
      if (start.name.empty() || start.ticks < 1 || start.ticks > kMaxStartTicks || !start.q.allFinite())
        throw ModelFileError("start '" + start.name + "' of " + movement_names[m] +
                             ": a start needs a name, 1.." + std::to_string(kMaxStartTicks) + " ticks and a finite q");
      list.push_back({{"name", start.name},
                      {"ticks", start.ticks},
                      {"q", std::vector<double>(start.q.data(), start.q.data() + kNumJoints)}});
    }
    s[movement_names[m]] = std::move(list);
  }
  j["starts"] = std::move(s);
  return j.dump();
}

namespace {

JointVector jointsOf(const Json& v, const std::string& origin, const std::string& where) {
  if (!v.is_array() || v.size() != static_cast<std::size_t>(kNumJoints))
    throw ModelFileError(origin + ": metadata \"workspace\" " + where + " is not " + std::to_string(kNumJoints) +
                         " joint angles");
  JointVector q;
  for (int k = 0; k < kNumJoints; ++k) {
    const Json& x = v[static_cast<std::size_t>(k)];
    if (!x.is_number() || !std::isfinite(x.get<double>()))
      throw ModelFileError(origin + ": metadata \"workspace\" " + where + " is not finite numbers");
    q[k] = x.get<double>();
  }
  return q;
}

}  // namespace

std::vector<ModelWorkspace> detail::workspaceFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names, const std::string& origin) {
  std::vector<ModelWorkspace> out;
  if (!j.is_object() || !j.contains("workspace")) return out;
  const Json& w = j["workspace"];
  if (!w.is_object()) throw ModelFileError(origin + ": metadata \"workspace\" is not an object of movements");
  for (auto it = w.begin(); it != w.end(); ++it)
    if (std::find(movement_names.begin(), movement_names.end(), it.key()) == movement_names.end())
      throw ModelFileError(origin + ": metadata \"workspace\" names '" + it.key() + "', which is not a movement of the model");
  for (const std::string& movement : movement_names) {
    if (!w.contains(movement) || !w[movement].is_object() || !w[movement].contains("lo") || !w[movement].contains("hi"))
      throw ModelFileError(origin + ": metadata \"workspace\" has no {lo, hi} for movement '" + movement + "'");
    ModelWorkspace e;
    e.lo = jointsOf(w[movement]["lo"], origin, "lo of '" + movement + "'");
    e.hi = jointsOf(w[movement]["hi"], origin, "hi of '" + movement + "'");
    if ((e.lo.array() > e.hi.array()).any())
      throw ModelFileError(origin + ": metadata \"workspace\" of '" + movement + "' has lo above hi");
    out.push_back(e);
  }
  // A demonstration begins at its start (the retargeted first pose): that is demonstrated too.
  const ModelStarts starts = detail::startsFromMetadata(j, movement_names, origin);
  for (std::size_t m = 0; m < out.size(); ++m)
    for (const ModelStart& st : starts[m]) {
      out[m].lo = out[m].lo.cwiseMin(st.q);
      out[m].hi = out[m].hi.cwiseMax(st.q);
    }
  return out;
}

std::string withModelWorkspace(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                               const std::vector<ModelWorkspace>& workspace) {
  Json j = metadata_json.empty() ? Json::object() : Json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw ModelFileError("the model's metadata is not a JSON object: cannot add \"workspace\"");
  if (workspace.size() != movement_names.size())
    throw ModelFileError("a workspace for " + std::to_string(workspace.size()) + " movements, the model has " +
                         std::to_string(movement_names.size()));
  Json w = Json::object();
  for (std::size_t m = 0; m < movement_names.size(); ++m)
    w[movement_names[m]] = {{"lo", std::vector<double>(workspace[m].lo.data(), workspace[m].lo.data() + kNumJoints)},
                            {"hi", std::vector<double>(workspace[m].hi.data(), workspace[m].hi.data() + kNumJoints)}};
  j["workspace"] = std::move(w);
  return j.dump();
}

}  // namespace nao
