// The metadata reader of model.bin (readModelSpec, nao/model_file.hpp) and its retargeting
// section.
#include "model_metadata_json.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

namespace nao {

RetargetParams detail::retargetFromMetadata(const MetadataJson& j, const RetargetParams& defaults,
                                            const std::string& origin) {
  RetargetParams r = defaults;
  if (!j.is_object() || !j.contains("data") || !j["data"].is_object() || !j["data"].contains("retarget") ||
      j["data"]["retarget"].is_null())
    return r;  // a model that does not say: the default (hand priority)
  const MetadataJson& s = j["data"]["retarget"];
  const std::string bad = origin + ": the model's metadata has an unusable data.retarget ";
  if (!s.is_object() || !s.contains("priority") || !s["priority"].is_string() ||
      !parseRetargetPriority(s["priority"].get<std::string>().c_str(), r.priority))
    throw std::runtime_error(bad + "(priority must be \"hand\" or \"joints\")");
  if (s.contains("lambda_q")) {
    if (!s["lambda_q"].is_number() || !(s["lambda_q"].get<double>() >= 0.0) || !std::isfinite(s["lambda_q"].get<double>()))
      throw std::runtime_error(bad + "(lambda_q must be a finite number >= 0)");
    r.lambda_q = s["lambda_q"].get<double>();
  }
  if (s.contains("posture_weights")) {
    const MetadataJson& w = s["posture_weights"];
    if (!w.is_array() || w.size() != static_cast<std::size_t>(kNumJoints))
      throw std::runtime_error(bad + "(posture_weights must hold " + std::to_string(kNumJoints) + " numbers)");
    for (int k = 0; k < kNumJoints; ++k) {
      const MetadataJson& x = w[static_cast<std::size_t>(k)];
      if (!x.is_number() || !(x.get<double>() > 0.0) || !std::isfinite(x.get<double>()))
        throw std::runtime_error(bad + "(posture_weights must be finite and > 0)");
      r.posture_weights[k] = x.get<double>();
    }
  }
  return r;
}

namespace {

// "split": {"train": [names], "val": [names]}; what is not a list of strings reads as none.
std::vector<std::string> splitNames(const detail::MetadataJson& j, const char* which) {
  std::vector<std::string> names;
  if (!j.is_object() || !j.contains("split") || !j["split"].is_object() || !j["split"].contains(which) ||
      !j["split"][which].is_array())
    return names;
  for (const detail::MetadataJson& n : j["split"][which])
    if (n.is_string()) names.push_back(n.get<std::string>());
  return names;
}

std::string dataFingerprint(const detail::MetadataJson& j) {
  if (j.is_object() && j.contains("data") && j["data"].is_object() && j["data"].contains("fingerprint") &&
      j["data"]["fingerprint"].is_string())
    return j["data"]["fingerprint"].get<std::string>();
  return {};
}

}  // namespace

ModelSpec readModelSpec(const ModelHeader& header, const RetargetParams& defaults, const std::string& origin) {
  const detail::MetadataJson j = detail::parseModelMetadata(header.metadata_json);
  ModelSpec spec;
  spec.movement_names = header.movement_names;
  spec.starts = detail::startsFromMetadata(j, header.movement_names, origin);
  spec.workspace = detail::workspaceFromMetadata(j, header.movement_names, origin);
  spec.run_codes = detail::runCodesFromMetadata(j, header.movement_names, static_cast<int>(header.arch.d_model), origin);
  spec.retarget = detail::retargetFromMetadata(j, defaults, origin);
  spec.split.train = splitNames(j, "train");
  spec.split.val = splitNames(j, "val");
  spec.data_fingerprint = dataFingerprint(j);
  return spec;
}

}  // namespace nao
