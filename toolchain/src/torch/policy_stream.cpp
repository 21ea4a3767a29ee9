#include "policy_stream.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace nao::tools {
namespace {

// The window's last W ticks: `cache` with the new tick's tokens appended, the oldest tick
// dropped once it holds more than W.
torch::Tensor append(const torch::Tensor& cache, const torch::Tensor& tokens, std::int64_t joints, std::int64_t window) {
  torch::Tensor out = cache.defined() ? torch::cat({cache, tokens}, 2) : tokens;
  if (out.size(2) > window * joints) out = out.slice(2, out.size(2) - window * joints);
  return out;
}

// The age of each key of a window of n ticks, oldest first: key token (τ, j) of tick index τ has
// age n − 1 − τ. [n·J].
torch::Tensor keyAges(std::int64_t n, std::int64_t joints) {
  return torch::arange(n - 1, -1, -1, torch::kInt64).repeat_interleave(joints);
}

// AttentionImpl::attendKV for the J queries of one tick, the same function: one tick's queries
// meet few keys, and batched matrix products of B·H such small matrices cost a library call
// each, where products and sums over whole tensors cost one pass. x [B,Jq,d], k, v [B,H,Nk,d_h],
// bias broadcast to [B,H,Jq,Nk].
torch::Tensor attendTick(const AttentionImpl& attn, const torch::Tensor& x, const torch::Tensor& k,
                         const torch::Tensor& v, const torch::Tensor& bias) {
  const std::int64_t n_batch = x.size(0), n_query = x.size(1), d = attn.wq.size(0), d_h = d / attn.heads;
  const torch::Tensor q = x.matmul(attn.wq).add(attn.bq).view({n_batch, n_query, attn.heads, d_h}).transpose(1, 2);
  const torch::Tensor scores = (q.unsqueeze(3) * k.unsqueeze(2)).sum(-1).div(std::sqrt(static_cast<double>(d_h))) + bias;
  const torch::Tensor a = torch::softmax(scores, -1);                       // [B,H,Jq,Nk]
  const torch::Tensor o = (a.unsqueeze(-1) * v.unsqueeze(2)).sum(3);        // [B,H,Jq,d_h]
  return o.transpose(1, 2).reshape({n_batch, n_query, d}).matmul(attn.wo).add(attn.bo);
}

}  // namespace

torch::Tensor streamStep(const PolicyNetImpl& net, PolicyStream& s, const StreamInput& in) {
  const PolicyArch& arch = net.arch();
  if (net.conditioning() != Conditioning::kAutonomous)
    throw std::invalid_argument("streamStep: an autonomous-mode net (a reference-mode one also adds its law)");
  const std::int64_t n_batch = in.q.size(0), J = arch.tokens, d = arch.d_model, W = arch.window, C = arch.chunk;
  if (s.enc_k.empty()) {
    s.enc_k.resize(net.enc.size());
    s.enc_v.resize(net.enc.size());
    s.cross_k.resize(net.dec.size());
    s.cross_v.resize(net.dec.size());
  }
  const std::int64_t n = std::min(s.ticks + 1, W);
  const torch::Tensor ages = keyAges(n, J);
  // The age bias of a layer's window [1,H,1,n·J].
  const auto ageBias = [&](const AttentionImpl& attn) { return attn.age_bias.index_select(1, ages).unsqueeze(1).unsqueeze(0); };
  const torch::Tensor qn = (in.q - net.q_mean) / net.q_std;
  const torch::Tensor an = (in.a_prev - net.a_mean) / net.a_std;
  // The tick's encoder tokens [B,J,d]: [qn, an, rn = 0] embedded, plus joint, movement, step, code.
  torch::Tensor x = net.embed_in->forward(torch::stack({qn, an, torch::zeros_like(qn)}, -1)) + net.joint_enc +
                    net.movement_emb.index_select(0, in.movement).unsqueeze(1) +
                    net.step_emb.index_select(0, in.step.clamp(0, arch.max_steps - 1)).unsqueeze(1);
  if (in.z.defined()) x = x + in.z.view({n_batch, 1, d});
  for (std::size_t l = 0; l < net.enc.size(); ++l) {
    const EncoderLayerImpl& layer = *net.enc[l];
    const torch::Tensor h = layer.ln1->forward(x);
    s.enc_k[l] = append(s.enc_k[l], layer.attn->keys(h), J, W);
    s.enc_v[l] = append(s.enc_v[l], layer.attn->values(h), J, W);
    x = x + attendTick(*layer.attn, h, s.enc_k[l], s.enc_v[l], ageBias(*layer.attn));
    x = x + layer.ffn->forward(layer.ln2->forward(x));
  }
  const torch::Tensor memory = net.enc_norm->forward(x);

  // The action tokens' self-attention: query i sees tokens 0..i (proximal → distal).
  const torch::Tensor causal = torch::ones({J, J}, torch::kBool).triu(1);
  const torch::Tensor self_bias = torch::zeros({J, J}).masked_fill(causal, -std::numeric_limits<float>::infinity());
  torch::Tensor y = net.embed_act->forward(an.unsqueeze(-1)) + net.joint_dec;  // [B,J,d]
  for (std::size_t l = 0; l < net.dec.size(); ++l) {
    const DecoderLayerImpl& layer = *net.dec[l];
    s.cross_k[l] = append(s.cross_k[l], layer.cross->keys(memory), J, W);
    s.cross_v[l] = append(s.cross_v[l], layer.cross->values(memory), J, W);
    const torch::Tensor h = layer.ln1->forward(y);
    y = y + attendTick(*layer.self, h, layer.self->keys(h), layer.self->values(h), self_bias);
    y = y + attendTick(*layer.cross, layer.ln2->forward(y), s.cross_k[l], s.cross_v[l], ageBias(*layer.cross));
    y = y + layer.ffn->forward(layer.ln3->forward(y));
  }
  // The chunk in rad [B,J,C]; the temporal ensemble (the runtime's ensembledAction) as a running
  // sum: entry k of the chunk made at t is for tick t + k, weighed exp(−decay k) wherever it is
  // used, so pending[k] holds the weighted entries for tick t + k of every chunk so far.
  const torch::Tensor chunk =
      net.head_chunk->forward(net.dec_norm->forward(y)) * net.a_std.view({1, -1, 1}) + net.a_mean.view({1, -1, 1});
  const double decay = C > 1 ? net.ensemble_decay.item<double>() : 0.0;
  const torch::Tensor weight = torch::exp(torch::arange(C, torch::kFloat32) * static_cast<float>(-decay));
  const torch::Tensor shifted =
      s.pending.defined() ? torch::constant_pad_nd(s.pending.slice(2, 1), {0, 1}) : torch::zeros_like(chunk);
  s.pending = shifted + chunk * weight;
  ++s.ticks;
  const std::int64_t have = std::min(s.ticks, C);
  double sum = 0.0;
  for (std::int64_t k = 0; k < have; ++k) sum += std::exp(-decay * static_cast<double>(k));
  return s.pending.select(2, 0) / sum;
}

}  // namespace nao::tools
