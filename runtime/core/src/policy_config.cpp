#include "nao/policy_config.hpp"

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

namespace {

// age_bias [H, W] (attention over time only): b_h(age) added to head h's score of a key
// `age` ticks older than its query; it depends on the age alone, so cached keys stay valid.
void addAttention(std::vector<TensorSpec>& m, const std::string& p, int d, int heads = 0, int window = 0) {
  for (const char* w : {"q", "k", "v", "o"}) {
    m.push_back({p + ".w" + w, {d, d}, TensorRole::kMatrix});
    m.push_back({p + ".b" + w, {d}});
  }
  if (heads > 0) m.push_back({p + ".age_bias", {heads, window}});
}

void addNorm(std::vector<TensorSpec>& m, const std::string& p, int d) {
  m.push_back({p + ".gain", {d}});
  m.push_back({p + ".bias", {d}});
}

void addFfn(std::vector<TensorSpec>& m, const std::string& p, const PolicyArch& a) {
  int in = a.d_model;
  for (std::size_t k = 0; k <= a.ffn_hidden.size(); ++k) {
    const int out = k < a.ffn_hidden.size() ? a.ffn_hidden[k] : a.d_model;
    m.push_back({p + "." + std::to_string(k) + ".weight", {in, out}, TensorRole::kMatrix});
    m.push_back({p + "." + std::to_string(k) + ".bias", {out}});
    in = out;
  }
}

}  // namespace

std::vector<TensorSpec> policyManifest(const PolicyArch& a) {
  const int d = a.d_model, J = a.tokens;
  std::vector<TensorSpec> m;
  m.push_back({"embed.in.weight", {a.features, d}});
  m.push_back({"embed.in.bias", {d}});
  m.push_back({"embed.joint_enc", {J, d}});
  m.push_back({"embed.movement", {a.movements, d}});
  m.push_back({"embed.step", {a.max_steps, d}});
  m.push_back({"embed.act.weight", {1, d}});
  m.push_back({"embed.act.bias", {d}});
  m.push_back({"embed.joint_dec", {J, d}});
  for (int l = 0; l < a.encoder_layers; ++l) {
    const std::string p = "enc." + std::to_string(l);
    addNorm(m, p + ".ln1", d);
    addAttention(m, p + ".attn", d, a.heads, a.window);
    addNorm(m, p + ".ln2", d);
    addFfn(m, p + ".ffn", a);
  }
  addNorm(m, "enc.norm", d);
  for (int l = 0; l < a.decoder_layers; ++l) {
    const std::string p = "dec." + std::to_string(l);
    addNorm(m, p + ".ln1", d);
    addAttention(m, p + ".self", d);
    addNorm(m, p + ".ln2", d);
    addAttention(m, p + ".cross", d, a.heads, a.window);
    addNorm(m, p + ".ln3", d);
    addFfn(m, p + ".ffn", a);
  }
  addNorm(m, "dec.norm", d);
  const int C = a.chunk;
  // Token j's row of the chunk: a_j(t) .. a_j(t+C-1), normalised.
  m.push_back({"head.weight", {d, C}});
  m.push_back({"head.bias", {C}});
  // w_k = exp(-decay k): the weight of the chunk made k ticks ago in the executed action.
  if (C > 1) m.push_back({"head.ensemble_decay", {1}, TensorRole::kFixed});
  // Laws the runtime adds to the network's action: gain_j r_j (reference mode; 0 autonomous).
  m.push_back({"law.gain", {J}, TensorRole::kFixed});
  for (const char* s : {"q", "a", "r"}) {
    m.push_back({std::string("norm.") + s + "_mean", {J}, TensorRole::kFixed});
    m.push_back({std::string("norm.") + s + "_std", {J}, TensorRole::kFixed});
  }
  m.push_back({"centroids", {a.movements, a.clusters, J}, TensorRole::kFixed});
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
