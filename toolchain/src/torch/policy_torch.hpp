// The policy of docs/policy.md as a libtorch module, for training (offline only).
//
// Every parameter and buffer is one manifest tensor (nao::policyManifest), under the same
// name and shape: matrices are stored [in, out] and applied as x.matmul(W) + b, attention is
// written out by hand (no torch::nn::Transformer), and the normalisation statistics and the
// centroids are buffers "norm.*" and "centroids". manifestTensors() lists them in manifest
// order; that list is what model.bin stores.
//
// Sequences: a batch holds B rollouts of T ticks from tick 0, J joints each; the
// encoder runs over the T·J tokens (τ, j) (index τ·J + j) with the sliding-window causal mask
// and age bias of the runtime (nao/policy.hpp), each token computed once per sequence.
//
// Shapes: B = batch, T = ticks, J = tokens (joints) per tick, d = d_model, H = heads, W = window.
#pragma once

#include "nao/policy_config.hpp"
#include "nao/tools/policy_dataset.hpp"

#include <torch/torch.h>

#include <string>
#include <utility>
#include <vector>

namespace nao::tools {

/// Normalised inputs of one batch of sequences (docs/policy.md "Inputs, normalised"). Every
/// sequence starts at tick 0; shorter ones are padded at the end (padding is never attended
/// by earlier ticks: the mask is causal in time).
struct PolicyBatch {
  torch::Tensor qn;        ///< [B,T,J] float
  torch::Tensor an;        ///< [B,T,J] float, normalised a(t-1)
  torch::Tensor rn;        ///< [B,T,J] float (ignored in autonomous mode: taken as 0)
  torch::Tensor movement;  ///< [B] int64
  torch::Tensor z = {};    ///< [B,d] float, a per-run code added to every encoder token (the runtime's run_code; undefined = 0)
};

/// The head's output for every tick of a batch (docs/policy.md "Head"), normalised units.
struct PolicyHeadOutput {
  torch::Tensor chunk;  ///< [B,T,J,C], token j's a_j(t) .. a_j(t+C-1)
};

/// The attention record of docs/policy.md, per batch element and tick.
struct PolicyAttention {
  std::vector<torch::Tensor> cross;  ///< per decoder layer: α summed over the window [B,T,H,J(action),J(body part)]
  torch::Tensor mass;                ///< [B,T,J] raw mass of the last cross-attention per body part
  torch::Tensor age_profile;         ///< [B,T,W] mass per age (0 = the query's own tick)
  torch::Tensor score;               ///< [B,T,J] norm-based score of the last cross-attention
  torch::Tensor cross_out;           ///< [B,T,J,d] last cross-attention output (after Wo, bo)
};

/// The sliding-window structure of T ticks: for query token (t, i) and key token (τ, j),
/// age = t − τ; allowed iff 0 <= age < W.
///
/// Two layouts of the same attention. Full: every query against all T·J keys, the pairs outside
/// the window blocked (cost and memory ∝ T²). Blocked: the ticks cut into nb blocks of W; the
/// queries of block b only meet the keys of blocks b−1 and b (2W ticks, block −1 being padding
/// before tick 0), which hold every key of their window (cost ∝ T). A blocked pair gets weight 0
/// in both, so they are the same function; the float sums run over fewer zeros in the blocked one.
struct WindowMask {
  std::int64_t ticks = 0;
  int joints = 0, window = 0;
  std::int64_t blocks = 0;  ///< nb > 0: the blocked layout; 0: the full one
  // Full layout:
  torch::Tensor age;      ///< [T·J, T·J] int64, clamped to 0..W-1
  torch::Tensor blocked;  ///< [T·J, T·J] bool: age < 0 or age >= W
  // Blocked layout (query token i of a block against key token k of its blocks b−1, b):
  torch::Tensor block_age;      ///< [W·J, 2W·J] int64, clamped to 0..W-1
  torch::Tensor block_blocked;  ///< [nb, W·J, 2W·J] bool (block 0 also blocks its padding keys)
};
enum class WindowLayout { kAuto, kFull, kBlocked };
/// kAuto takes the blocked layout when its score count (nb·2W² per joint pair) is below the
/// full one's (T²): from T ≈ 2.2 W on.
WindowMask windowMask(std::int64_t ticks, int joints, int window, WindowLayout layout = WindowLayout::kAuto);

/// x W + b with W stored [in, out] ("weight", "bias").
class AffineImpl : public torch::nn::Module {
 public:
  AffineImpl(int in, int out);
  torch::Tensor forward(const torch::Tensor& x) const { return x.matmul(weight).add(bias); }
  torch::Tensor weight, bias;
};
TORCH_MODULE(Affine);

/// Pre-layer norm: (x - mean) / sqrt(var + 1e-5) * gain + bias over the last dimension.
class LayerNormImpl : public torch::nn::Module {
 public:
  explicit LayerNormImpl(int d);
  torch::Tensor forward(const torch::Tensor& x) const;
  torch::Tensor gain, bias;
};
TORCH_MODULE(LayerNorm);

/// Multi-head attention with wq, bq, wk, bk, wv, bv, wo, bo ([d,d] / [d]); with a window
/// (temporal attention) also age_bias [H,W].
class AttentionImpl : public torch::nn::Module {
 public:
  AttentionImpl(int d, int heads, int window = 0);
  /// x [B,Jq,d] queries, z [B,Jk,d] keys/values; causal: query i sees keys 0..i.
  /// alpha (if given) receives α [B,H,Jq,Jk]; values (if given) receives V [B,H,Jk,d_h].
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& z, bool causal,
                        torch::Tensor* alpha = nullptr, torch::Tensor* values = nullptr) const;
  /// Over the window: x, z [B,T·J,d] tokens of the same T ticks; scores get age_bias[h, age]
  /// and the blocked pairs of `mask` are excluded.
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& z, const WindowMask& mask,
                        torch::Tensor* alpha = nullptr, torch::Tensor* values = nullptr) const;
  /// The keys and the values of tokens z [B,N,d] in the heads' layout [B,H,N,d_h].
  torch::Tensor keys(const torch::Tensor& z) const;
  torch::Tensor values(const torch::Tensor& z) const;
  /// Queries x [B,Jq,d] against keys and values k, v [B,H,Nk,d_h] (keys(), values()), the scores
  /// plus `bias` (broadcast to [B,H,Jq,Nk]; undefined: none): the output after wo, bo [B,Jq,d];
  /// alpha (if given) receives α [B,H,Jq,Nk]. What every form of the attention computes.
  torch::Tensor attendKV(const torch::Tensor& x, const torch::Tensor& k, const torch::Tensor& v, const torch::Tensor& bias,
                         torch::Tensor* alpha = nullptr) const;
  int heads;
  torch::Tensor wq, bq, wk, bk, wv, bv, wo, bo, age_bias;

 private:
  torch::Tensor attend(const torch::Tensor& x, const torch::Tensor& z, const torch::Tensor& bias,
                       torch::Tensor* alpha, torch::Tensor* values) const;
  torch::Tensor attendBlocked(const torch::Tensor& x, const torch::Tensor& z, const WindowMask& mask,
                              torch::Tensor* alpha, torch::Tensor* values) const;
};
TORCH_MODULE(Attention);

/// ReLU MLP d - h0 - ... - d, layers "0".."n" (ReLU after every layer but the last).
class FfnImpl : public torch::nn::Module {
 public:
  FfnImpl(int d, const std::vector<int>& hidden);
  torch::Tensor forward(torch::Tensor x) const;
  std::vector<Affine> layers;
};
TORCH_MODULE(Ffn);

class EncoderLayerImpl : public torch::nn::Module {
 public:
  EncoderLayerImpl(const PolicyArch& arch);
  torch::Tensor forward(torch::Tensor x, const WindowMask& mask) const;
  LayerNorm ln1{nullptr}, ln2{nullptr};
  Attention attn{nullptr};
  Ffn ffn{nullptr};
};
TORCH_MODULE(EncoderLayer);

class DecoderLayerImpl : public torch::nn::Module {
 public:
  DecoderLayerImpl(const PolicyArch& arch);
  /// y [B,T,J,d] action tokens, memory [B,T·J,d]. alpha/values/cross_out (if given) receive the
  /// cross-attention's α [B,H,T·J,T·J], V [B,H,T·J,d_h] and output [B,T,J,d].
  torch::Tensor forward(torch::Tensor y, const torch::Tensor& memory, const WindowMask& mask,
                        torch::Tensor* alpha = nullptr, torch::Tensor* values = nullptr,
                        torch::Tensor* cross_out = nullptr) const;
  LayerNorm ln1{nullptr}, ln2{nullptr}, ln3{nullptr};
  Attention self{nullptr}, cross{nullptr};
  Ffn ffn{nullptr};
};
TORCH_MODULE(DecoderLayer);

/// The whole encoder-decoder with its normalisation and centroid buffers.
class PolicyNetImpl : public torch::nn::Module {
 public:
  /// Parameters initialised per docs/policy.md from torch's global generator (seed it first with
  /// torch::manual_seed): matrices Xavier-uniform, biases 0, LN gain 1 / bias 0, embeddings
  /// N(0, 0.02²); embed.step zero and frozen (requires_grad false) in reference mode. Buffers:
  /// norm means 0, stds 1, centroids 0. Throws std::invalid_argument for an unusable
  /// architecture.
  PolicyNetImpl(const PolicyArch& arch, Conditioning conditioning);

  /// The head's output for a normalised batch of sequences; fills `attention` if given (memory
  /// grows as (T·J)² · d: for short sequences, tests and analysis).
  PolicyHeadOutput forward(const PolicyBatch& batch, PolicyAttention* attention = nullptr) const;

  /// The actions a(t) in rad [B,T,J] the runtime executes, from raw sequences in rad (q, a(t-1),
  /// r: [B,T,J] float; movement [B] int64), normalised with the norm.* buffers (rn = 0 in
  /// autonomous mode): the chunks de-normalised, temporally ensembled over the last C
  /// ticks (head.ensemble_decay), plus law.gain ⊙ r in reference mode. `net_action` (if given)
  /// receives the ensembled chunks alone, the network's share.
  torch::Tensor act(const torch::Tensor& q, const torch::Tensor& a_prev, const torch::Tensor& r,
                    const torch::Tensor& movement, PolicyAttention* attention = nullptr,
                    torch::Tensor* net_action = nullptr) const;

  /// Stores the statistics in the norm.* buffers.
  void setNormalisation(const NormStats& stats);
  /// Stores the centroids [M][K] in the "centroids" buffer [M,K,J].
  void setCentroids(const std::vector<std::vector<JointVector>>& centroids);
  /// Stores the temporal ensemble's decay per tick of age in head.ensemble_decay (C > 1 only).
  void setEnsembleDecay(double decay);
  /// Stores the law the runtime adds in reference mode, gain_j r_j, in law.gain (0 autonomous).
  void setLawGain(double gain);

  /// The parameters the optimiser updates (everything but a frozen embed.step).
  std::vector<torch::Tensor> trainableParameters() const;

  const PolicyArch& arch() const { return arch_; }
  Conditioning conditioning() const { return conditioning_; }

  /// How forward() lays out the window attention (WindowMask): the same function either way;
  /// kAuto takes the cheaper one for the sequence length.
  WindowLayout window_layout = WindowLayout::kAuto;

 private:
  PolicyArch arch_;
  Conditioning conditioning_;

 public:
  // embed.*
  std::shared_ptr<torch::nn::Module> embed;
  Affine embed_in{nullptr}, embed_act{nullptr};
  torch::Tensor joint_enc, movement_emb, step_emb, joint_dec;
  // enc.l.*, enc.norm, dec.l.*, dec.norm, head
  std::vector<EncoderLayer> enc;
  std::vector<DecoderLayer> dec;
  LayerNorm enc_norm{nullptr}, dec_norm{nullptr};
  // head.*: head.weight [d,C], head.bias [C]; C > 1: head.ensemble_decay [1] (buffer).
  // law.gain [J] (buffer).
  Affine head_chunk{nullptr};
  torch::Tensor ensemble_decay, law_gain;
  // norm.* and centroids (buffers)
  torch::Tensor q_mean, q_std, a_mean, a_std, r_mean, r_std, centroids;
};
TORCH_MODULE(PolicyNet);

/// Every manifest tensor of `net` (parameters and buffers), in manifest order. Throws
/// std::logic_error if a manifest name is missing, has another shape, or the module holds a
/// tensor the manifest does not list.
std::vector<std::pair<std::string, torch::Tensor>> manifestTensors(const PolicyNet& net);

/// manifestTensors as contiguous float vectors (what encodeModel takes).
std::vector<std::vector<float>> manifestFloats(const PolicyNet& net);

}  // namespace nao::tools
