// The run codes of model.bin's metadata (nao/model_file.hpp: modelRunCodes, withModelRunCodes).
#include "model_metadata_json.hpp"
#include "nao/model_file.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace nao {
namespace {

using Json = nlohmann::ordered_json;

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw ModelFileError(origin + ": metadata \"run_codes\" " + what);
}

const Json& listOf(const Json& e, const char* key, std::size_t n, const std::string& origin, const std::string& where) {
  if (!e.contains(key) || !e[key].is_array() || e[key].size() != n)
    fail(origin, where + "has no \"" + key + "\" list of " + std::to_string(n) + " entries (one per name)");
  return e[key];
}

/// `v` as `n` finite numbers, or fail.
template <class Out>
void numbers(const Json& v, std::size_t n, Out* out, const std::string& origin, const std::string& what) {
  if (!v.is_array() || v.size() != n) fail(origin, what + " is not " + std::to_string(n) + " numbers");
  for (std::size_t k = 0; k < n; ++k) {
    if (!v[k].is_number() || !std::isfinite(v[k].get<double>())) fail(origin, what + " has a number that is not finite");
    out[k] = static_cast<Out>(v[k].get<double>());
  }
}

}  // namespace

std::vector<ModelRunCodes> detail::runCodesFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names, int d_model, const std::string& origin) {
  std::vector<ModelRunCodes> out;
  if (!j.is_object() || !j.contains("run_codes")) return out;
  const Json& rc = j["run_codes"];
  if (!rc.is_object()) fail(origin, "is not an object of movements");
  for (auto it = rc.begin(); it != rc.end(); ++it)
    if (std::find(movement_names.begin(), movement_names.end(), it.key()) == movement_names.end())
      fail(origin, "names '" + it.key() + "', which is not a movement of the model");
  for (const std::string& movement : movement_names) {
    if (!rc.contains(movement) || !rc[movement].is_object()) fail(origin, "has no entry for movement '" + movement + "'");
    const Json& e = rc[movement];
    const std::string where = "of '" + movement + "' ";
    if (!e.contains("names") || !e["names"].is_array()) fail(origin, where + "has no \"names\" list");
    const std::size_t n = e["names"].size();
    ModelRunCodes c;
    c.d = d_model;
    c.q.resize(n);
    c.code.resize(n * static_cast<std::size_t>(d_model));
    c.dtw_m.resize(n * n);
    const Json &q = listOf(e, "q", n, origin, where), &code = listOf(e, "code", n, origin, where),
               &dtw = listOf(e, "dtw_m", n, origin, where);
    for (std::size_t i = 0; i < n; ++i) {
      const std::string at = where + "entry " + std::to_string(i);
      if (!e["names"][i].is_string() || e["names"][i].get<std::string>().empty())
        fail(origin, at + " has no name (a non-empty string)");
      c.names.push_back(e["names"][i].get<std::string>());
      numbers(q[i], kNumJoints, c.q[i].data(), origin, at + "'s q");
      numbers(code[i], static_cast<std::size_t>(d_model), c.code.data() + i * static_cast<std::size_t>(d_model), origin,
              at + "'s code (d_model " + std::to_string(d_model) + ")");
      numbers(dtw[i], n, c.dtw_m.data() + i * n, origin, at + "'s dtw_m row");
    }
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t k = 0; k < n; ++k)
        if (c.dtw_m[i * n + k] < 0.0 || c.dtw_m[i * n + k] != c.dtw_m[k * n + i] || (i == k && c.dtw_m[i * n + k] != 0.0))
          fail(origin, where + "has a dtw_m table that is not symmetric, non-negative with a zero diagonal");
    out.push_back(std::move(c));
  }
  return out;
}

std::string withModelRunCodes(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                              const std::vector<ModelRunCodes>& codes) {
  Json j = metadata_json.empty() ? Json::object() : Json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw ModelFileError("the model's metadata is not a JSON object: cannot add \"run_codes\"");
  if (codes.size() != movement_names.size())
    throw ModelFileError("run codes for " + std::to_string(codes.size()) + " movements, the model has " +
                         std::to_string(movement_names.size()));
  Json rc = Json::object();
  for (std::size_t m = 0; m < movement_names.size(); ++m) {
    const ModelRunCodes& c = codes[m];
    const std::size_t n = c.size(), d = static_cast<std::size_t>(c.d);
    if (c.q.size() != n || c.code.size() != n * d || c.dtw_m.size() != n * n)
      throw ModelFileError("run codes of " + movement_names[m] + ": names, q, code (n × d) and dtw_m (n × n) do not match");
    Json q = Json::array(), code = Json::array(), dtw = Json::array();
    for (std::size_t i = 0; i < n; ++i) {
      q.push_back(std::vector<double>(c.q[i].data(), c.q[i].data() + kNumJoints));
      code.push_back(std::vector<float>(c.code.begin() + static_cast<std::ptrdiff_t>(i * d),
                                        c.code.begin() + static_cast<std::ptrdiff_t>((i + 1) * d)));
      dtw.push_back(std::vector<double>(c.dtw_m.begin() + static_cast<std::ptrdiff_t>(i * n),
                                        c.dtw_m.begin() + static_cast<std::ptrdiff_t>((i + 1) * n)));
    }
    rc[movement_names[m]] = {{"names", c.names}, {"q", std::move(q)}, {"code", std::move(code)}, {"dtw_m", std::move(dtw)}};
  }
  j["run_codes"] = std::move(rc);
  return j.dump();
}

}  // namespace nao
