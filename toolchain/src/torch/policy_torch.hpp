// The policy of docs/policy.md as a libtorch module, for training (offline only).
//
// Every parameter and buffer is one manifest tensor (nao::policyManifest), under the same
// name and shape: matrices are stored [in, out] and applied as x.matmul(W) + b, attention is
// written out by hand (no torch::nn::Transformer), and the normalisation statistics and the
// centroids are buffers "norm.*" and "centroids". manifestTensors() lists them in manifest
// order; that list is what model.bin stores.
//
// Shapes: B = batch, J = tokens (joints), d = d_model, H = heads.
#pragma once

#include "nao/policy_config.hpp"
#include "nao/tools/policy_dataset.hpp"

#include <torch/torch.h>

#include <string>
#include <utility>
#include <vector>

namespace nao::tools {

/// Normalised inputs of one batch (docs/policy.md "Inputs, normalised").
struct PolicyBatch {
  torch::Tensor qn;        ///< [B,J] float
  torch::Tensor an;        ///< [B,J] float, normalised a(t-1)
  torch::Tensor rn;        ///< [B,J] float (ignored in autonomous mode: taken as 0)
  torch::Tensor movement;  ///< [B] int64
  torch::Tensor step;      ///< [B] int64, already clamped to max_steps - 1
};

/// The attention record of docs/policy.md, per batch element.
struct PolicyAttention {
  std::vector<torch::Tensor> cross;  ///< per decoder layer: α [B,H,J(action),J(body part)]
  torch::Tensor score;               ///< [B,J] norm-based score of the last cross-attention
  torch::Tensor cross_out;           ///< [B,J,d] last cross-attention output (after Wo, bo)
};

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

/// Multi-head attention with wq, bq, wk, bk, wv, bv, wo, bo ([d,d] / [d]).
class AttentionImpl : public torch::nn::Module {
 public:
  AttentionImpl(int d, int heads);
  /// x [B,Jq,d] queries, z [B,Jk,d] keys/values; causal: query i sees keys 0..i.
  /// alpha (if given) receives α [B,H,Jq,Jk]; values (if given) receives V [B,H,Jk,d_h].
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& z, bool causal,
                        torch::Tensor* alpha = nullptr, torch::Tensor* values = nullptr) const;
  int heads;
  torch::Tensor wq, bq, wk, bk, wv, bv, wo, bo;
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
  torch::Tensor forward(torch::Tensor x) const;
  LayerNorm ln1{nullptr}, ln2{nullptr};
  Attention attn{nullptr};
  Ffn ffn{nullptr};
};
TORCH_MODULE(EncoderLayer);

class DecoderLayerImpl : public torch::nn::Module {
 public:
  DecoderLayerImpl(const PolicyArch& arch);
  /// alpha/values/cross_out (if given) receive the cross-attention's α, V and output.
  torch::Tensor forward(torch::Tensor y, const torch::Tensor& memory, torch::Tensor* alpha = nullptr,
                        torch::Tensor* values = nullptr, torch::Tensor* cross_out = nullptr) const;
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
  /// norm means 0, stds 1, centroids 0.
  PolicyNetImpl(const PolicyArch& arch, Conditioning conditioning);

  /// Normalised action an' [B,J] for a normalised batch; fills `attention` if given.
  torch::Tensor forward(const PolicyBatch& batch, PolicyAttention* attention = nullptr) const;

  /// The action a(t) in rad [B,J] from raw inputs in rad (q, a(t-1), r: [B,J] float; movement,
  /// step: [B] int64), normalised with the norm.* buffers (rn = 0 in autonomous mode).
  torch::Tensor act(const torch::Tensor& q, const torch::Tensor& a_prev, const torch::Tensor& r,
                    const torch::Tensor& movement, const torch::Tensor& step,
                    PolicyAttention* attention = nullptr) const;

  /// Stores the statistics in the norm.* buffers.
  void setNormalisation(const NormStats& stats);
  /// Stores the centroids [M][K] in the "centroids" buffer [M,K,J].
  void setCentroids(const std::vector<std::vector<JointVector>>& centroids);

  /// The parameters the optimiser updates (everything but a frozen embed.step).
  std::vector<torch::Tensor> trainableParameters() const;

  const PolicyArch& arch() const { return arch_; }
  Conditioning conditioning() const { return conditioning_; }

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
  Affine head{nullptr};
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
