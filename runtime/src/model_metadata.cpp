// Metadata readers of model.bin (nao/model_metadata.hpp).
#include "nao/model_metadata.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

namespace nao {

float modelResidualGain(const std::string& metadata_json, const std::string& origin) {
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("training") || !j["training"].is_object() ||
      !j["training"].contains("residual_gain"))
    return 0.0f;
  const nlohmann::json& g = j["training"]["residual_gain"];
  if (!g.is_number() || !std::isfinite(g.get<double>()) || !(g.get<double>() >= 0.0) || g.get<double>() > 100.0)
    throw std::runtime_error(origin + ": the model's metadata has an unusable training.residual_gain (a number in [0, 100])");
  return static_cast<float>(g.get<double>());
}

std::int64_t modelPhaseTicks(const std::string& metadata_json, const std::string& origin) {
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("training") || !j["training"].is_object() || !j["training"].contains("phase_ticks"))
    return 0;
  const nlohmann::json& v = j["training"]["phase_ticks"];
  if (!v.is_number_integer() || v.get<std::int64_t>() < 1 || v.get<std::int64_t>() > 100000)
    throw std::runtime_error(origin + ": the model's metadata has an unusable training.phase_ticks (an integer in [1, 100000])");
  return v.get<std::int64_t>();
}

LinearArCoefficients modelLinearAr(const std::string& metadata_json, int movements, const std::string& origin) {
  LinearArCoefficients k;
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("training") || !j["training"].is_object() || !j["training"].contains("linear_ar"))
    return k;
  const auto bad = [&](const std::string& what) {
    return std::runtime_error(origin + ": the model's metadata has an unusable training.linear_ar (" + what + ")");
  };
  const auto number = [&](const nlohmann::json& v) {
    if (!v.is_number() || !std::isfinite(v.get<double>())) throw bad("a coefficient is not a finite number");
    return v.get<double>();
  };
  const nlohmann::json& ar = j["training"]["linear_ar"];
  if (!ar.is_array() || ar.size() != static_cast<std::size_t>(movements))
    throw bad("not one entry per movement (" + std::to_string(movements) + ")");
  for (const nlohmann::json& mv : ar) {
    if (!mv.is_array() || mv.size() != 5) throw bad("not 5 joints per movement");
    std::array<double, 5> c{}, beta{};
    std::array<std::array<double, 5>, kPolicyArMaxOrder> alpha{};
    for (std::size_t jj = 0; jj < 5; ++jj) {
      const nlohmann::json& e = mv[jj];
      if (!e.is_object() || !e.contains("c") || !e.contains("beta") || !e.contains("alpha") || !e["alpha"].is_array())
        throw bad("a joint without c, beta and alpha");
      const std::size_t order = e["alpha"].size();
      if (order < 1 || order > static_cast<std::size_t>(kPolicyArMaxOrder))
        throw bad("an order outside 1.." + std::to_string(kPolicyArMaxOrder));
      c[jj] = number(e["c"]);
      beta[jj] = number(e["beta"]);
      for (std::size_t i = 0; i < order; ++i) alpha[i][jj] = number(e["alpha"][i]);
    }
    k.c.push_back(c);
    k.beta.push_back(beta);
    k.alpha.push_back(alpha);
  }
  return k;
}

RetargetParams modelRetargetSetting(const std::string& metadata_json, const RetargetParams& defaults,
                                    const std::string& origin) {
  RetargetParams r = defaults;
  const nlohmann::json j = nlohmann::json::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("data") || !j["data"].is_object() || !j["data"].contains("retarget") ||
      j["data"]["retarget"].is_null())
    return r;  // a model that does not say: the default (hand priority)
  const nlohmann::json& s = j["data"]["retarget"];
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
    const nlohmann::json& w = s["posture_weights"];
    if (!w.is_array() || w.size() != static_cast<std::size_t>(kNumJoints))
      throw std::runtime_error(bad + "(posture_weights must hold " + std::to_string(kNumJoints) + " numbers)");
    for (int k = 0; k < kNumJoints; ++k) {
      const nlohmann::json& x = w[static_cast<std::size_t>(k)];
      if (!x.is_number() || !(x.get<double>() > 0.0) || !std::isfinite(x.get<double>()))
        throw std::runtime_error(bad + "(posture_weights must be finite and > 0)");
      r.posture_weights[k] = x.get<double>();
    }
  }
  return r;
}

}  // namespace nao
