#include "policy_torch.hpp"

#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

namespace nao::tools {
namespace {

std::string lastComponent(const std::string& name) { return name.substr(name.rfind('.') + 1); }

std::vector<std::int64_t> shape64(const std::vector<int>& shape) { return {shape.begin(), shape.end()}; }

// Every parameter and buffer of the module tree by its dotted name, and whether it is a buffer.
std::map<std::string, std::pair<torch::Tensor, bool>> namedTensors(const torch::nn::Module& m) {
  std::map<std::string, std::pair<torch::Tensor, bool>> out;
  for (const auto& p : m.named_parameters()) out.emplace(p.key(), std::pair{p.value(), false});
  for (const auto& b : m.named_buffers()) out.emplace(b.key(), std::pair{b.value(), true});
  return out;
}

// The module's tensors in manifest order, checked against the manifest's names, shapes and
// roles (a buffer is a TensorRole::kFixed tensor, a parameter a trained one).
std::vector<std::pair<std::string, torch::Tensor>> inManifestOrder(const torch::nn::Module& m, const PolicyArch& arch) {
  std::map<std::string, std::pair<torch::Tensor, bool>> named = namedTensors(m);
  std::vector<std::pair<std::string, torch::Tensor>> out;
  for (const TensorSpec& spec : policyManifest(arch)) {
    const auto it = named.find(spec.name);
    if (it == named.end()) throw std::logic_error("policy module has no tensor '" + spec.name + "'");
    const auto& [tensor, buffer] = it->second;
    if (tensor.sizes().vec() != shape64(spec.shape))
      throw std::logic_error("policy module tensor '" + spec.name + "' has shape " + c10::str(tensor.sizes()) +
                             ", the manifest says " + c10::str(shape64(spec.shape)));
    if (buffer != (spec.role == TensorRole::kFixed))
      throw std::logic_error("policy module tensor '" + spec.name + "' is a " + (buffer ? "buffer" : "parameter") +
                             ", the manifest says it is " + (buffer ? "trained" : "set from the data"));
    out.emplace_back(spec.name, tensor);
    named.erase(it);
  }
  if (!named.empty()) throw std::logic_error("policy module tensor '" + named.begin()->first + "' is not in the manifest");
  return out;
}

}  // namespace

AffineImpl::AffineImpl(int in, int out) {
  weight = register_parameter("weight", torch::empty({in, out}));
  bias = register_parameter("bias", torch::empty({out}));
}

LayerNormImpl::LayerNormImpl(int d) {
  gain = register_parameter("gain", torch::empty({d}));
  bias = register_parameter("bias", torch::empty({d}));
}

torch::Tensor LayerNormImpl::forward(const torch::Tensor& x) const {
  // Biased variance over d, eps 1e-5: exactly docs/policy.md's LN.
  return torch::layer_norm(x, {gain.size(0)}, gain, bias, 1e-5);
}

WindowMask windowMask(std::int64_t ticks, int joints, int window, WindowLayout layout) {
  WindowMask m;
  m.ticks = ticks;
  m.joints = joints;
  m.window = window;
  const std::int64_t nb = (ticks + window - 1) / window;
  const bool blocked = layout == WindowLayout::kBlocked ||
                       (layout == WindowLayout::kAuto && nb * 2 * window * window < ticks * ticks);
  if (!blocked) {
    const torch::Tensor tick = torch::arange(ticks, torch::kInt64).repeat_interleave(joints);  // tick of token
    const torch::Tensor age = tick.unsqueeze(1) - tick.unsqueeze(0);                          // [query, key]
    m.blocked = age.lt(0).logical_or(age.ge(window));
    m.age = age.clamp(0, window - 1);
    return m;
  }
  m.blocks = nb;
  // Query tick i of block b is tick bW + i; key tick k of the pair of blocks is (b−1)W + k.
  const torch::Tensor q_tick = torch::arange(window, torch::kInt64).repeat_interleave(joints) + window;
  const torch::Tensor k_tick = torch::arange(2 * window, torch::kInt64).repeat_interleave(joints);
  const torch::Tensor age = q_tick.unsqueeze(1) - k_tick.unsqueeze(0);  // [W·J, 2W·J]
  m.block_age = age.clamp(0, window - 1);
  m.block_blocked = age.lt(0).logical_or(age.ge(window)).unsqueeze(0).repeat({nb, 1, 1});
  m.block_blocked.select(0, 0).slice(1, 0, static_cast<std::int64_t>(window) * joints).fill_(true);  // before tick 0
  return m;
}

AttentionImpl::AttentionImpl(int d, int n_heads, int window) : heads(n_heads) {
  wq = register_parameter("wq", torch::empty({d, d}));
  bq = register_parameter("bq", torch::empty({d}));
  wk = register_parameter("wk", torch::empty({d, d}));
  bk = register_parameter("bk", torch::empty({d}));
  wv = register_parameter("wv", torch::empty({d, d}));
  bv = register_parameter("bv", torch::empty({d}));
  wo = register_parameter("wo", torch::empty({d, d}));
  bo = register_parameter("bo", torch::empty({d}));
  if (window > 0) age_bias = register_parameter("age_bias", torch::empty({n_heads, window}));
}

torch::Tensor AttentionImpl::forward(const torch::Tensor& x, const torch::Tensor& z, bool causal, torch::Tensor* alpha,
                                     torch::Tensor* values) const {
  torch::Tensor bias;
  if (causal)
    bias = torch::zeros({x.size(1), z.size(1)})
               .masked_fill(torch::ones({x.size(1), z.size(1)}, torch::kBool).triu(1),
                            -std::numeric_limits<float>::infinity());
  return attend(x, z, bias, alpha, values);
}

torch::Tensor AttentionImpl::forward(const torch::Tensor& x, const torch::Tensor& z, const WindowMask& mask,
                                     torch::Tensor* alpha, torch::Tensor* values) const {
  if (mask.blocks > 0) return attendBlocked(x, z, mask, alpha, values);
  // [H, query, key]: the head's bias of the pair's age; blocked pairs -inf.
  const torch::Tensor bias =
      age_bias.index_select(1, mask.age.reshape({-1}))
          .view({heads, mask.age.size(0), mask.age.size(1)})
          .masked_fill(mask.blocked, -std::numeric_limits<float>::infinity());
  return attend(x, z, bias, alpha, values);
}

torch::Tensor AttentionImpl::keys(const torch::Tensor& z) const {
  const std::int64_t d_h = wq.size(0) / heads;
  return z.matmul(wk).add(bk).view({z.size(0), z.size(1), heads, d_h}).transpose(1, 2);
}

torch::Tensor AttentionImpl::values(const torch::Tensor& z) const {
  const std::int64_t d_h = wq.size(0) / heads;
  return z.matmul(wv).add(bv).view({z.size(0), z.size(1), heads, d_h}).transpose(1, 2);
}

torch::Tensor AttentionImpl::attendKV(const torch::Tensor& x, const torch::Tensor& k, const torch::Tensor& v,
                                      const torch::Tensor& bias, torch::Tensor* alpha) const {
  const std::int64_t n_batch = x.size(0), n_query = x.size(1), d = wq.size(0);
  const std::int64_t d_h = d / heads;
  // [B,J,d] -> [B,H,J,d_h]: head h owns columns h*d_h .. (h+1)*d_h - 1.
  const torch::Tensor q = x.matmul(wq).add(bq).view({n_batch, n_query, heads, d_h}).transpose(1, 2);
  torch::Tensor scores = q.matmul(k.transpose(-2, -1)).div(std::sqrt(static_cast<double>(d_h)));
  if (bias.defined()) scores = scores + bias;
  const torch::Tensor a = torch::softmax(scores, -1);
  if (alpha) *alpha = a;
  const torch::Tensor o = a.matmul(v).transpose(1, 2).reshape({n_batch, n_query, d});
  return o.matmul(wo).add(bo);
}

torch::Tensor AttentionImpl::attend(const torch::Tensor& x, const torch::Tensor& z, const torch::Tensor& bias,
                                    torch::Tensor* alpha, torch::Tensor* values_out) const {
  const torch::Tensor v = values(z);
  if (values_out) *values_out = v;
  return attendKV(x, keys(z), v, bias, alpha);
}

torch::Tensor AttentionImpl::attendBlocked(const torch::Tensor& x, const torch::Tensor& z, const WindowMask& mask,
                                           torch::Tensor* alpha, torch::Tensor* values) const {
  const std::int64_t n_batch = x.size(0), d = wq.size(0), d_h = d / heads;
  const std::int64_t wj = static_cast<std::int64_t>(mask.window) * mask.joints, nb = mask.blocks;
  const std::int64_t n_tok = mask.ticks * mask.joints, pad_end = nb * wj - n_tok;
  // Queries [B,H,nb,WJ,d_h]; keys and values of blocks −1..nb−1 [B,H,nb+1,WJ,d_h], then each
  // block's pair (b−1, b) side by side [B,H,nb,2WJ,d_h]. Padding tokens are zeros, always blocked.
  const auto blocks = [&](const torch::Tensor& t, std::int64_t n) {
    return t.view({n_batch, n, wj, heads, d_h}).permute({0, 3, 1, 2, 4});
  };
  const auto pairs = [&](const torch::Tensor& t) {
    const torch::Tensor b = blocks(torch::constant_pad_nd(t, {0, 0, wj, pad_end}), nb + 1);
    return torch::cat({b.slice(2, 0, nb), b.slice(2, 1, nb + 1)}, 3);
  };
  const torch::Tensor q = blocks(torch::constant_pad_nd(x.matmul(wq).add(bq), {0, 0, 0, pad_end}), nb);
  const torch::Tensor v_tokens = z.matmul(wv).add(bv);
  const torch::Tensor k = pairs(z.matmul(wk).add(bk)), v = pairs(v_tokens);
  const torch::Tensor bias = age_bias.index_select(1, mask.block_age.reshape({-1}))
                                 .view({heads, 1, wj, 2 * wj})
                                 .expand({heads, nb, wj, 2 * wj})
                                 .masked_fill(mask.block_blocked, -std::numeric_limits<float>::infinity());
  const torch::Tensor scores = q.matmul(k.transpose(-2, -1)).div(std::sqrt(static_cast<double>(d_h))) + bias;
  const torch::Tensor a = torch::softmax(scores, -1);  // [B,H,nb,WJ,2WJ]
  if (alpha) {
    // Back to the full layout's [B,H,T·J,T·J] (zeros outside the window), for the record.
    torch::Tensor full = torch::zeros({n_batch, heads, nb * wj, (nb + 1) * wj}, a.options());
    for (std::int64_t b = 0; b < nb; ++b)
      full.slice(2, b * wj, (b + 1) * wj).slice(3, b * wj, (b + 2) * wj).copy_(a.select(2, b));
    *alpha = full.slice(2, 0, n_tok).slice(3, wj, wj + n_tok);
  }
  if (values) *values = v_tokens.view({n_batch, n_tok, heads, d_h}).transpose(1, 2);
  const torch::Tensor o = a.matmul(v).permute({0, 2, 3, 1, 4}).reshape({n_batch, nb * wj, d}).slice(1, 0, n_tok);
  return o.matmul(wo).add(bo);
}

FfnImpl::FfnImpl(int d, const std::vector<int>& hidden) {
  int in = d;
  for (std::size_t k = 0; k <= hidden.size(); ++k) {
    const int out = k < hidden.size() ? hidden[k] : d;
    layers.push_back(register_module(std::to_string(k), Affine(in, out)));
    in = out;
  }
}

torch::Tensor FfnImpl::forward(torch::Tensor x) const {
  for (std::size_t k = 0; k < layers.size(); ++k) {
    x = layers[k]->forward(x);
    if (k + 1 < layers.size()) x = torch::relu(x);
  }
  return x;
}

EncoderLayerImpl::EncoderLayerImpl(const PolicyArch& arch) {
  ln1 = register_module("ln1", LayerNorm(arch.d_model));
  attn = register_module("attn", Attention(arch.d_model, arch.heads, arch.window));
  ln2 = register_module("ln2", LayerNorm(arch.d_model));
  ffn = register_module("ffn", Ffn(arch.d_model, arch.ffn_hidden));
}

torch::Tensor EncoderLayerImpl::forward(torch::Tensor x, const WindowMask& mask) const {
  const torch::Tensor h = ln1->forward(x);
  x = x + attn->forward(h, h, mask);
  return x + ffn->forward(ln2->forward(x));
}

DecoderLayerImpl::DecoderLayerImpl(const PolicyArch& arch) {
  ln1 = register_module("ln1", LayerNorm(arch.d_model));
  self = register_module("self", Attention(arch.d_model, arch.heads));
  ln2 = register_module("ln2", LayerNorm(arch.d_model));
  cross = register_module("cross", Attention(arch.d_model, arch.heads, arch.window));
  ln3 = register_module("ln3", LayerNorm(arch.d_model));
  ffn = register_module("ffn", Ffn(arch.d_model, arch.ffn_hidden));
}

torch::Tensor DecoderLayerImpl::forward(torch::Tensor y, const torch::Tensor& memory, const WindowMask& mask,
                                        torch::Tensor* alpha, torch::Tensor* values, torch::Tensor* cross_out) const {
  const std::int64_t n_batch = y.size(0), n_ticks = y.size(1), n_joints = y.size(2), d = y.size(3);
  // Self-attention among the J action tokens of each tick (masked proximal -> distal).
  const torch::Tensor h = ln1->forward(y).reshape({n_batch * n_ticks, n_joints, d});
  y = y + self->forward(h, h, true).view({n_batch, n_ticks, n_joints, d});
  // Cross-attention of tick t's action tokens to the memory of ticks t-W+1..t.
  const torch::Tensor c = cross->forward(ln2->forward(y).reshape({n_batch, n_ticks * n_joints, d}), memory, mask, alpha,
                                         values)
                              .view({n_batch, n_ticks, n_joints, d});
  if (cross_out) *cross_out = c;
  y = y + c;
  return y + ffn->forward(ln3->forward(y));
}

PolicyNetImpl::PolicyNetImpl(const PolicyArch& arch, Conditioning conditioning)
    : arch_(arch), conditioning_(conditioning) {
  const std::string problem = archProblem(arch);
  if (!problem.empty()) throw std::invalid_argument("policy architecture: " + problem);
  const int d = arch.d_model, n_joints = arch.tokens;

  embed = register_module("embed", std::make_shared<torch::nn::Module>());
  embed_in = embed->register_module("in", Affine(arch.features, d));
  joint_enc = embed->register_parameter("joint_enc", torch::empty({n_joints, d}));
  movement_emb = embed->register_parameter("movement", torch::empty({arch.movements, d}));
  step_emb = embed->register_parameter("step", torch::empty({arch.max_steps, d}),
                                       conditioning == Conditioning::kAutonomous);
  embed_act = embed->register_module("act", Affine(1, d));
  joint_dec = embed->register_parameter("joint_dec", torch::empty({n_joints, d}));

  auto enc_holder = register_module("enc", std::make_shared<torch::nn::Module>());
  for (int l = 0; l < arch.encoder_layers; ++l)
    enc.push_back(enc_holder->register_module(std::to_string(l), EncoderLayer(arch)));
  enc_norm = enc_holder->register_module("norm", LayerNorm(d));
  auto dec_holder = register_module("dec", std::make_shared<torch::nn::Module>());
  for (int l = 0; l < arch.decoder_layers; ++l)
    dec.push_back(dec_holder->register_module(std::to_string(l), DecoderLayer(arch)));
  dec_norm = dec_holder->register_module("norm", LayerNorm(d));
  const int C = arch.chunk;
  head_chunk = register_module("head", Affine(d, C));
  if (C > 1) ensemble_decay = head_chunk->register_buffer("ensemble_decay", torch::zeros({1}));
  auto law = register_module("law", std::make_shared<torch::nn::Module>());
  law_gain = law->register_buffer("gain", torch::zeros({n_joints}));

  auto norm = register_module("norm", std::make_shared<torch::nn::Module>());
  q_mean = norm->register_buffer("q_mean", torch::zeros({n_joints}));
  q_std = norm->register_buffer("q_std", torch::ones({n_joints}));
  a_mean = norm->register_buffer("a_mean", torch::zeros({n_joints}));
  a_std = norm->register_buffer("a_std", torch::ones({n_joints}));
  r_mean = norm->register_buffer("r_mean", torch::zeros({n_joints}));
  r_std = norm->register_buffer("r_std", torch::ones({n_joints}));
  centroids = register_buffer("centroids", torch::zeros({arch.movements, arch.clusters, n_joints}));

  // Initialise in manifest order, so the draws from the seeded generator do not depend on how
  // the module tree happens to be registered.
  torch::NoGradGuard no_grad;
  const std::vector<TensorSpec> manifest = policyManifest(arch_);
  const std::vector<std::pair<std::string, torch::Tensor>> tensors = inManifestOrder(*this, arch_);
  for (std::size_t i = 0; i < tensors.size(); ++i) {
    const auto& [name, tensor] = tensors[i];
    if (manifest[i].role == TensorRole::kFixed) continue;  // buffers, set above
    torch::Tensor t = tensor;
    const std::string last = lastComponent(name);
    if (name == "embed.step" && conditioning == Conditioning::kReference)
      t.zero_();
    else if (name == "embed.joint_enc" || name == "embed.movement" || name == "embed.step" || name == "embed.joint_dec")
      t.normal_(0.0, 0.02);
    else if (last == "age_bias")
      t.zero_();  // no preference of age at the start: attention learns it
    else if (last == "gain")
      t.fill_(1.0);
    else if (last == "bias" || last == "bq" || last == "bk" || last == "bv" || last == "bo")
      t.zero_();
    else if (last == "weight" || last == "wq" || last == "wk" || last == "wv" || last == "wo")
      torch::nn::init::xavier_uniform_(t);
    else
      throw std::logic_error("no initialisation rule for '" + name + "'");
  }
}

PolicyHeadOutput PolicyNetImpl::forward(const PolicyBatch& batch, PolicyAttention* attention) const {
  const std::int64_t n_batch = batch.qn.size(0), n_ticks = batch.qn.size(1), n_joints = arch_.tokens;
  const std::int64_t d = arch_.d_model, n_heads = arch_.heads, window = arch_.window;
  const torch::Tensor rn =
      conditioning_ == Conditioning::kAutonomous ? torch::zeros_like(batch.qn) : batch.rn;
  // Encoder tokens (τ, j): [qn, an, rn] embedded, plus joint, movement and the tick's step row.
  const torch::Tensor tick = torch::arange(n_ticks, torch::kInt64);
  const torch::Tensor step_rows = step_emb.index_select(0, tick.clamp_max(arch_.max_steps - 1)).view({1, n_ticks, 1, d});
  torch::Tensor x = embed_in->forward(torch::stack({batch.qn, batch.an, rn}, -1));  // [B,T,J,d]
  x = x + joint_enc + movement_emb.index_select(0, batch.movement).view({n_batch, 1, 1, d}) + step_rows;
  if (batch.z.defined()) x = x + batch.z.view({n_batch, 1, 1, d});
  x = x.reshape({n_batch, n_ticks * n_joints, d});
  const WindowMask mask = windowMask(n_ticks, static_cast<int>(n_joints), static_cast<int>(window), window_layout);
  for (const EncoderLayer& layer : enc) x = layer->forward(x, mask);
  const torch::Tensor memory = enc_norm->forward(x);

  torch::Tensor y = embed_act->forward(batch.an.unsqueeze(-1)) + joint_dec;  // [B,T,J,d]
  torch::Tensor alpha, values, cross_out;
  if (attention) attention->cross.clear();
  for (const DecoderLayer& layer : dec) {
    y = layer->forward(y, memory, mask, attention ? &alpha : nullptr, attention ? &values : nullptr,
                       attention ? &cross_out : nullptr);
    if (attention)  // α summed over the window's ticks per body part: [B,T,H,J,J]
      attention->cross.push_back(alpha.view({n_batch, n_heads, n_ticks, n_joints, n_ticks, n_joints})
                                     .sum(4)
                                     .permute({0, 2, 1, 3, 4}));
  }
  if (attention) {
    const torch::Tensor a6 = alpha.view({n_batch, n_heads, n_ticks, n_joints, n_ticks, n_joints});
    attention->mass = a6.sum(4).mean(3).mean(1);  // [B,T,J]
    // Mass per age: key tick τ = t - age.
    const torch::Tensor per_key_tick = a6.sum(5).mean(3).mean(1);  // [B,T(query),T(key)]
    torch::Tensor profile = torch::zeros({n_batch, n_ticks, window});
    for (std::int64_t age = 0; age < window && age < n_ticks; ++age)
      profile.select(2, age).slice(1, age, n_ticks).copy_(per_key_tick.diagonal(-age, 1, 2));
    attention->age_profile = profile;
    // Norm-based score: f_h(M_k) = V_h[k] Wo_h; score[t][j] = Σ_i Σ_τ ‖Σ_h α_h[(t,i)][(τ,j)] f_h(M_(τ,j))‖.
    const torch::Tensor wo = dec.back()->cross->wo.view({n_heads, d / n_heads, d});
    const torch::Tensor f = values.matmul(wo);                                   // [B,H,TJ,d]
    const torch::Tensor g = torch::einsum("bhqk,bhkd->bqkd", {alpha, f});        // [B,TJ,TJ,d]
    attention->score = g.norm(2, -1).view({n_batch, n_ticks, n_joints, n_ticks, n_joints}).sum({2, 3});
    attention->cross_out = cross_out;
  }
  const torch::Tensor h = dec_norm->forward(y);  // [B,T,J,d]
  PolicyHeadOutput out;
  out.chunk = head_chunk->forward(h);  // [B,T,J,C]
  return out;
}

torch::Tensor PolicyNetImpl::act(const torch::Tensor& q, const torch::Tensor& a_prev, const torch::Tensor& r,
                                 const torch::Tensor& movement, PolicyAttention* attention,
                                 torch::Tensor* net_action) const {
  PolicyBatch batch;
  batch.qn = (q - q_mean) / q_std;
  batch.an = (a_prev - a_mean) / a_std;
  batch.rn = (r - r_mean) / r_std;
  batch.movement = movement;
  // [B,T,J,C] in rad.
  const torch::Tensor chunk = forward(batch, attention).chunk * a_std.view({1, 1, -1, 1}) + a_mean.view({1, 1, -1, 1});
  const std::int64_t n_ticks = chunk.size(1), C = arch_.chunk;
  // The temporal ensemble (the runtime's ensembledAction): tick t takes entry k of the chunk
  // made at t − k, for every k < min(t + 1, C), weighted exp(−decay k) / Σ over those k.
  const double decay = C > 1 ? ensemble_decay.item<double>() : 0.0;
  torch::Tensor a = torch::zeros_like(chunk.select(3, 0));
  for (std::int64_t t = 0; t < n_ticks; ++t) {
    const std::int64_t have = std::min<std::int64_t>(t + 1, C);
    double sum = 0.0;
    for (std::int64_t k = 0; k < have; ++k) sum += std::exp(-decay * static_cast<double>(k));
    for (std::int64_t k = 0; k < have; ++k) {
      const auto w = static_cast<float>(std::exp(-decay * static_cast<double>(k)) / sum);
      a.select(1, t).add_(chunk.select(1, t - k).select(2, k) * w);
    }
  }
  if (net_action) *net_action = a.clone();
  if (conditioning_ == Conditioning::kReference) a = a + law_gain * r;
  return a;
}

void PolicyNetImpl::setNormalisation(const NormStats& s) {
  torch::NoGradGuard no_grad;
  const auto put = [](torch::Tensor& t, const JointVector& v) {
    for (int j = 0; j < kNumJoints; ++j) t[j] = static_cast<float>(v[j]);
  };
  put(q_mean, s.q_mean);
  put(q_std, s.q_std);
  put(a_mean, s.a_mean);
  put(a_std, s.a_std);
  put(r_mean, s.r_mean);
  put(r_std, s.r_std);
}

void PolicyNetImpl::setCentroids(const std::vector<std::vector<JointVector>>& c) {
  if (static_cast<std::int64_t>(c.size()) != centroids.size(0))
    throw std::invalid_argument("centroids of " + std::to_string(c.size()) + " movements, the architecture has " +
                                std::to_string(centroids.size(0)));
  torch::NoGradGuard no_grad;
  auto acc = centroids.accessor<float, 3>();
  for (std::size_t m = 0; m < c.size(); ++m) {
    if (static_cast<std::int64_t>(c[m].size()) != centroids.size(1))
      throw std::invalid_argument("movement " + std::to_string(m) + " has " + std::to_string(c[m].size()) +
                                  " centroids, the architecture has " + std::to_string(centroids.size(1)));
    for (std::size_t k = 0; k < c[m].size(); ++k)
      for (int j = 0; j < kNumJoints; ++j)
        acc[static_cast<std::int64_t>(m)][static_cast<std::int64_t>(k)][j] = static_cast<float>(c[m][k][j]);
  }
}

void PolicyNetImpl::setEnsembleDecay(double decay) {
  if (arch_.chunk == 1) return;  // one chunk entry per tick: nothing to weigh
  torch::NoGradGuard no_grad;
  ensemble_decay.fill_(decay);
}

void PolicyNetImpl::setLawGain(double gain) {
  torch::NoGradGuard no_grad;
  law_gain.fill_(conditioning_ == Conditioning::kReference ? gain : 0.0);
}

std::vector<torch::Tensor> PolicyNetImpl::trainableParameters() const {
  std::vector<torch::Tensor> out;
  for (const auto& [name, t] : inManifestOrder(*this, arch_))
    if (t.requires_grad()) out.push_back(t);
  return out;
}

std::vector<std::pair<std::string, torch::Tensor>> manifestTensors(const PolicyNet& net) {
  return inManifestOrder(*net, net->arch());
}

std::vector<std::vector<float>> manifestFloats(const PolicyNet& net) {
  std::vector<std::vector<float>> out;
  for (const auto& [name, t] : manifestTensors(net)) {
    const torch::Tensor c = t.detach().to(torch::kFloat).contiguous();
    const float* p = c.data_ptr<float>();
    out.emplace_back(p, p + c.numel());
  }
  return out;
}

}  // namespace nao::tools
