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

ModelSpec readModelSpec(const ModelHeader& header, const RetargetParams& defaults, const std::string& origin) {
  const detail::MetadataJson j = detail::parseModelMetadata(header.metadata_json);
  ModelSpec spec;
  spec.starts = detail::startsFromMetadata(j, header.movement_names, origin);
  spec.workspace = detail::workspaceFromMetadata(j, header.movement_names, origin);
  spec.run_codes = detail::runCodesFromMetadata(j, header.movement_names, static_cast<int>(header.arch.d_model), origin);
  spec.retarget = detail::retargetFromMetadata(j, defaults, origin);
  return spec;
}

}  // namespace nao
