#include "nao/policy_config.hpp"
#include "nao/policy_manifest.hpp"

#include <string>

namespace nao {

const char* conditioningName(Conditioning c) {
  switch (c) {
    case Conditioning::kReference: return "reference";
    case Conditioning::kAutonomous: return "autonomous";
  }
  return "unknown";
}

bool PolicyArch::operator==(const PolicyArch& o) const {
  return d_model == o.d_model && heads == o.heads && encoder_layers == o.encoder_layers &&
         decoder_layers == o.decoder_layers && ffn_hidden == o.ffn_hidden && tokens == o.tokens &&
         features == o.features && movements == o.movements && clusters == o.clusters && max_steps == o.max_steps &&
         window == o.window && chunk == o.chunk;
}

PolicyArch paperArch() { return PolicyArch{}; }

PolicyArch smallArch() {
  PolicyArch a;
  a.d_model = 32;
  a.heads = 4;
  a.encoder_layers = 2;
  a.decoder_layers = 2;
  a.ffn_hidden = {64, 64, 64};
  a.window = 8;
  return a;
}

std::string archProblem(const PolicyArch& a) {
  auto positive = [](int v, int cap) { return v >= 1 && v <= cap; };
  if (!positive(a.d_model, 4096)) return "d_model " + std::to_string(a.d_model) + " is not in 1..4096";
  if (!positive(a.heads, 64)) return "heads " + std::to_string(a.heads) + " is not in 1..64";
  if (a.d_model % a.heads != 0)
    return "d_model " + std::to_string(a.d_model) + " is not a multiple of heads " + std::to_string(a.heads);
  if (!positive(a.encoder_layers, 64)) return "encoder_layers " + std::to_string(a.encoder_layers) + " is not in 1..64";
  if (!positive(a.decoder_layers, 64)) return "decoder_layers " + std::to_string(a.decoder_layers) + " is not in 1..64";
  if (a.ffn_hidden.empty() || a.ffn_hidden.size() > 4) return "ffn_hidden must list 1 to 4 widths";
  for (int w : a.ffn_hidden)
    if (!positive(w, 16384)) return "ffn hidden width " + std::to_string(w) + " is not in 1..16384";
  if (a.tokens != 5) return "tokens " + std::to_string(a.tokens) + " (the NAO arm has 5 joints)";
  if (a.features != kPolicyFeatures) return "features " + std::to_string(a.features) + " (expected 3: q, a, r)";
  if (!positive(a.movements, 256)) return "movements " + std::to_string(a.movements) + " is not in 1..256";
  if (!positive(a.clusters, 1000)) return "clusters " + std::to_string(a.clusters) + " is not in 1..1000";
  if (!positive(a.max_steps, 100000)) return "max_steps " + std::to_string(a.max_steps) + " is not in 1..100000";
  if (!positive(a.window, 1000)) return "window " + std::to_string(a.window) + " is not in 1..1000 ticks";
  if (!positive(a.chunk, 100)) return "chunk " + std::to_string(a.chunk) + " is not in 1..100 ticks";
  return {};
}

std::size_t TensorSpec::count() const {
  std::size_t n = 1;
  for (int s : shape) n *= static_cast<std::size_t>(s);
  return n;
}

std::vector<TensorSpec> policyManifest(const PolicyArch& a) {
  std::vector<TensorSpec> m;
  walkPolicyManifest(a, [&m](const detail::ViewName& name, const ManifestShape& shape, TensorRole role, const auto&) {
    m.push_back({name.str(), std::vector<int>(shape.dim.begin(), shape.dim.begin() + shape.rank), role});
  });
  return m;
}

TensorExtent viewExtent(const TensorSpec& spec) {
  TensorExtent e;
  if (!spec.shape.empty()) e.rows = spec.shape.back();
  for (std::size_t k = 0; k + 1 < spec.shape.size(); ++k) e.cols *= spec.shape[k];
  return e;
}

std::size_t parameterCount(const PolicyArch& arch) {
  std::size_t n = 0;
  for (const TensorSpec& t : policyManifest(arch)) n += t.count();
  return n;
}

}  // namespace nao
