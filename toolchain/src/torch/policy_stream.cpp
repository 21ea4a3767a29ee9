#include "policy_stream.hpp"

#include <cmath>
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

// The age bias of a window of n ticks, oldest first: key token (τ, j) of tick index τ has age
// n − 1 − τ. [1,H,1,n·J].
torch::Tensor ageBias(const AttentionImpl& attn, std::int64_t n, std::int64_t joints) {
  const torch::Tensor age = torch::arange(n - 1, -1, -1, torch::kInt64).repeat_interleave(joints);
  return attn.age_bias.index_select(1, age).unsqueeze(1).unsqueeze(0);
}

}  // namespace

torch::Tensor streamStep(const PolicyNetImpl& net, PolicyStream& s, const StreamInput& in) {
  const PolicyArch& arch = net.arch();
  if (net.conditioning() != Conditioning::kAutonomous)
    throw std::invalid_argument("streamStep: an autonomous-mode net (a reference-mode one also adds its law)");
  if (arch.bins > 0) throw std::invalid_argument("streamStep: a regression head (bins heads are not streamed)");
  const std::int64_t n_batch = in.q.size(0), J = arch.tokens, d = arch.d_model, W = arch.window, C = arch.chunk;
  if (s.enc_k.empty()) {
    s.enc_k.resize(net.enc.size());
    s.enc_v.resize(net.enc.size());
    s.cross_k.resize(net.dec.size());
    s.cross_v.resize(net.dec.size());
  }
  const torch::Tensor qn = (in.q - net.q_mean) / net.q_std;
  const torch::Tensor an = (in.a_prev - net.a_mean) / net.a_std;
  // The tick's encoder tokens [B,J,d]: [qn, an, rn = 0] embedded, plus joint, movement, step, code.
  torch::Tensor x = net.embed_in->forward(torch::stack({qn, an, torch::zeros_like(qn)}, -1)) + net.joint_enc +
                    net.movement_emb.index_select(0, in.movement).unsqueeze(1) +
                    net.step_emb.index_select(0, in.step.clamp(0, arch.max_steps - 1)).unsqueeze(1);
  if (in.z.defined()) x = x + in.z.view({n_batch, 1, d});
  const std::int64_t n = std::min(s.ticks + 1, W);
  for (std::size_t l = 0; l < net.enc.size(); ++l) {
    const EncoderLayerImpl& layer = *net.enc[l];
    const torch::Tensor h = layer.ln1->forward(x);
    s.enc_k[l] = append(s.enc_k[l], layer.attn->keys(h), J, W);
    s.enc_v[l] = append(s.enc_v[l], layer.attn->values(h), J, W);
    x = x + layer.attn->attendKV(h, s.enc_k[l], s.enc_v[l], ageBias(*layer.attn, n, J));
    x = x + layer.ffn->forward(layer.ln2->forward(x));
  }
  const torch::Tensor memory = net.enc_norm->forward(x);

  torch::Tensor y = net.embed_act->forward(an.unsqueeze(-1)) + net.joint_dec;  // [B,J,d]
  for (std::size_t l = 0; l < net.dec.size(); ++l) {
    const DecoderLayerImpl& layer = *net.dec[l];
    s.cross_k[l] = append(s.cross_k[l], layer.cross->keys(memory), J, W);
    s.cross_v[l] = append(s.cross_v[l], layer.cross->values(memory), J, W);
    const torch::Tensor h = layer.ln1->forward(y);
    y = y + layer.self->forward(h, h, true);
    y = y + layer.cross->attendKV(layer.ln2->forward(y), s.cross_k[l], s.cross_v[l], ageBias(*layer.cross, n, J));
    y = y + layer.ffn->forward(layer.ln3->forward(y));
  }
  // The chunk in rad [B,J,C], then the temporal ensemble (the runtime's ensembledAction).
  const torch::Tensor chunk =
      net.head_chunk->forward(net.dec_norm->forward(y)) * net.a_std.view({1, -1, 1}) + net.a_mean.view({1, -1, 1});
  s.chunks.push_back(chunk);
  if (static_cast<std::int64_t>(s.chunks.size()) > C) s.chunks.erase(s.chunks.begin());
  ++s.ticks;
  const double decay = C > 1 ? net.ensemble_decay.item<double>() : 0.0;
  const auto have = static_cast<std::int64_t>(s.chunks.size());
  double sum = 0.0;
  for (std::int64_t k = 0; k < have; ++k) sum += std::exp(-decay * static_cast<double>(k));
  torch::Tensor a;
  for (std::int64_t k = 0; k < have; ++k) {
    const auto w = static_cast<float>(std::exp(-decay * static_cast<double>(k)) / sum);
    const torch::Tensor term = s.chunks[static_cast<std::size_t>(have - 1 - k)].select(2, k) * w;
    a = a.defined() ? a + term : term;
  }
  return a;
}

}  // namespace nao::tools
