// The policy's model: the compile-time dimensions of its computation
// (PolicyDims), the read-only views of every manifest tensor (PolicyWeights: model.bin data,
// .incbin'd by codegen or copied into aligned storage), their binding by manifest name or at
// generated offsets, and the int8 and packed fp32 copies the step may read instead. The step that
// reads them is policy.hpp's. Binding is configure-time code; the views themselves are plain
// Eigen::Map.
//
// Layout: a manifest matrix [in, out] row-major is the same bytes as a column-major Eigen
// [out, in] matrix, so y = W x with W the view (the docs' row-vector `x W`).
#pragma once

#include "nao/policy_config.hpp"
#include "nao/policy_kernels.hpp"
#include "nao/policy_manifest.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace nao {

/// Compile-time dimensions of a policy's computation. The runtime supports exactly three
/// FFN hidden layers; a model.bin with another count has a different PolicyArch and is rejected
/// by checkPolicyArch. The sizes of the model's tables - movements M, key poses K, step rows S,
/// and the action chunk C - are the bound model's (PolicyWeights), not
/// compile-time: they are lookups and a small head, and one compiled runtime serves every model
/// of these dimensions, whatever movements it was trained on (docs/policy.md).
template <int D, int H, int LE, int LD, int F0, int F1, int F2, int W = 20>
struct PolicyDims {
  static constexpr int kDModel = D;
  static constexpr int kHeads = H;
  static constexpr int kHeadDim = D / H;
  static constexpr int kEncoderLayers = LE;
  static constexpr int kDecoderLayers = LD;
  static constexpr int kFfn0 = F0;
  static constexpr int kFfn1 = F1;
  static constexpr int kFfn2 = F2;
  static constexpr int kTokens = 5;
  static constexpr int kFeatures = kPolicyFeatures;
  static constexpr int kWindow = W;               ///< ticks of history, the current one included
  static constexpr int kMemory = W * kTokens;     ///< tokens in a full window

  static_assert(D >= 1 && H >= 1 && D % H == 0, "d_model must be a positive multiple of heads");
  static_assert(LE >= 1 && LD >= 1, "at least one encoder and one decoder layer");
  static_assert(F0 >= 1 && F1 >= 1 && F2 >= 1, "FFN hidden widths must be positive");
  static_assert(W >= 1, "the window holds at least the current tick");
  // The key/value rings are [d, W J] fixed-size matrices, under the same cap.
  static_assert(static_cast<std::size_t>(D) * W * kTokens * sizeof(float) <= EIGEN_STACK_ALLOCATION_LIMIT,
                "a [d, W J] key/value ring exceeds Eigen's fixed-size limit");
  static_assert(kFeatures == 3, "token features are q, a(t-1), r");
  // Workspace buffers are fixed-size Eigen matrices, which Eigen caps at 128 KiB each.
  static_assert(static_cast<std::size_t>(std::max({D, F0, F1, F2})) * kTokens * sizeof(float) <=
                    EIGEN_STACK_ALLOCATION_LIMIT,
                "a [width, J] activation buffer exceeds Eigen's fixed-size limit");

  /// The same dimensions as a runtime PolicyArch (allocates; configure time only); the table and
  /// head sizes are PolicyArch's defaults.
  static PolicyArch arch() {
    PolicyArch a;
    a.d_model = D;
    a.heads = H;
    a.encoder_layers = LE;
    a.decoder_layers = LD;
    a.ffn_hidden = {F0, F1, F2};
    a.tokens = kTokens;
    a.features = kFeatures;
    a.window = W;
    return a;
  }
};

/// paperArch() (paper §4.1) and smallArch() (tests) as compiled dimensions.
using PaperPolicyDims = PolicyDims<128, 4, 4, 4, 512, 512, 512, 20>;
using SmallPolicyDims = PolicyDims<32, 4, 2, 2, 64, 64, 64, 8>;

/// True if the compiled Dims compute `arch`'s step (d_model, heads, layers, FFN, tokens,
/// features, window; the table sizes and the chunk are the bound model's).
template <class Dims>
bool computesPolicyArch(const PolicyArch& arch) {
  const PolicyArch c = Dims::arch();
  return arch.d_model == c.d_model && arch.heads == c.heads && arch.encoder_layers == c.encoder_layers &&
         arch.decoder_layers == c.decoder_layers && arch.ffn_hidden == c.ffn_hidden && arch.tokens == c.tokens &&
         arch.features == c.features && arch.window == c.window;
}

/// f(D{}) with the first D of the compiled dimensions `D, Ds...` that computes `arch`'s step: a
/// program built for several architectures runs the one a model.bin needs (configure time).
/// Throws std::invalid_argument when none does.
template <class D, class... Ds, class F>
decltype(auto) withPolicyDims(const PolicyArch& arch, F&& f) {
  if (computesPolicyArch<D>(arch)) return std::forward<F>(f)(D{});
  if constexpr (sizeof...(Ds) > 0) {
    return withPolicyDims<Ds...>(arch, std::forward<F>(f));
  } else {
    throw std::invalid_argument("no compiled policy dimensions compute this model's step (d_model " +
                                std::to_string(arch.d_model) + ", window " + std::to_string(arch.window) +
                                "): nao_codegen MODEL --out DIR writes its own");
  }
}

/// Largest action chunk C a runtime holds (the workspace's chunk ring); archProblem's cap is
/// above, bindPolicyWeights refuses a model beyond it.
inline constexpr int kPolicyMaxChunk = 32;

/// Read-only fixed-size view of one manifest tensor, Eigen shape [rows, cols] column-major. R or C
/// Eigen::Dynamic: that extent is the bound model's (tables and head; PolicyDims).
template <int R, int C>
using WeightView = Eigen::Map<const Eigen::Matrix<float, R, C>>;

/// The copy of one [Out, In] weight matrix that the step reads instead of its fp32 view, if
/// bound: the int8 copy (policy_kernels.hpp "Reduced precision": the pair-interleaved bytes and
/// the per-row scales, bindQuantizedWeights) or the packed fp32 copy (policy_kernels.hpp
/// "Packed fp32": the same floats in the kernels' block order, the same bits as the view,
/// bindPackedWeights). All null: the matrix runs from its fp32 view (the reference).
template <int Out, int In>
struct QuantView {
  static constexpr int kOut = Out, kIn = In;
  const std::int8_t* w = nullptr;     ///< Out·In bytes
  const float* scale = nullptr;       ///< Out floats
  const float* packed = nullptr;      ///< Out·In floats (packed fp32 models only)
};

template <class Dims>
struct LayerNormWeights {
  WeightView<Dims::kDModel, 1> gain{nullptr};
  WeightView<Dims::kDModel, 1> bias{nullptr};
};

/// One multi-head attention block; matrices [out = d, in = d].
template <class Dims>
struct AttentionWeights {
  static constexpr int D = Dims::kDModel;
  WeightView<D, D> wq{nullptr}, wk{nullptr}, wv{nullptr}, wo{nullptr};
  WeightView<D, 1> bq{nullptr}, bk{nullptr}, bv{nullptr}, bo{nullptr};
  QuantView<D, D> wq8, wk8, wv8, wo8;  ///< int8 models only
};

/// Attention over the window: plus age_bias(age, h), added to head h's score of a key `age`
/// ticks older than the query (manifest [H, W]).
template <class Dims>
struct TemporalAttentionWeights : AttentionWeights<Dims> {
  WeightView<Dims::kWindow, Dims::kHeads> age_bias{nullptr};
};

/// d -> F0 -> F1 -> F2 -> d, ReLU after each hidden layer.
template <class Dims>
struct FfnWeights {
  static constexpr int D = Dims::kDModel, F0 = Dims::kFfn0, F1 = Dims::kFfn1, F2 = Dims::kFfn2;
  WeightView<F0, D> w0{nullptr};
  WeightView<F0, 1> b0{nullptr};
  WeightView<F1, F0> w1{nullptr};
  WeightView<F1, 1> b1{nullptr};
  WeightView<F2, F1> w2{nullptr};
  WeightView<F2, 1> b2{nullptr};
  WeightView<D, F2> w3{nullptr};
  WeightView<D, 1> b3{nullptr};
  QuantView<F0, D> w0q;  ///< int8 models only
  QuantView<F1, F0> w1q;
  QuantView<F2, F1> w2q;
  QuantView<D, F2> w3q;
};

template <class Dims>
struct EncoderLayerWeights {
  LayerNormWeights<Dims> ln1;
  TemporalAttentionWeights<Dims> attn;  ///< over the window's tokens, causal in time
  LayerNormWeights<Dims> ln2;
  FfnWeights<Dims> ffn;
};

template <class Dims>
struct DecoderLayerWeights {
  LayerNormWeights<Dims> ln1;
  AttentionWeights<Dims> self;   ///< causal self-attention of the action tokens
  LayerNormWeights<Dims> ln2;
  TemporalAttentionWeights<Dims> cross;  ///< queries: action tokens; keys/values: the window's memory
  LayerNormWeights<Dims> ln3;
  FfnWeights<Dims> ffn;
};

/// The immutable model: views of every manifest tensor, the table and head sizes of the bound
/// model, and the conditioning mode. Built by bindPolicyWeights. Bound from a ModelFile
/// (nao/model_weights.hpp) the weights share ownership of the floats their views read
/// (`storage`), so they and every copy of them stay valid whatever happens to the file; bound
/// from pointers or an image the bytes stay the caller's.
template <class Dims>
struct PolicyWeights {
  static constexpr int D = Dims::kDModel, J = Dims::kTokens;
  static constexpr int X = Eigen::Dynamic;

  // Sizes of the bound model (its PolicyArch).
  int movements = 1;  ///< M
  int clusters = 1;   ///< K key poses per movement
  int max_steps = 1;  ///< S step rows
  int chunk = 1;      ///< C actions per token and tick

  WeightView<D, 3> embed_in_weight{nullptr};   ///< columns: q, a(t-1), r features
  WeightView<D, 1> embed_in_bias{nullptr};
  WeightView<D, J> embed_joint_enc{nullptr};   ///< column j: encoder embedding of joint j
  WeightView<D, X> embed_movement{nullptr, D, 0};  ///< [d, M], column m: movement m
  WeightView<D, X> embed_step{nullptr, D, 0};      ///< [d, S], column s: step s (zero in reference mode)
  WeightView<D, 1> embed_act_weight{nullptr};
  WeightView<D, 1> embed_act_bias{nullptr};
  WeightView<D, J> embed_joint_dec{nullptr};   ///< column j: decoder embedding of joint j
  std::array<EncoderLayerWeights<Dims>, Dims::kEncoderLayers> enc;
  LayerNormWeights<Dims> enc_norm;
  std::array<DecoderLayerWeights<Dims>, Dims::kDecoderLayers> dec;
  LayerNormWeights<Dims> dec_norm;
  // The head (docs/policy.md "Head"), normalised units: a regression of the chunk.
  WeightView<X, D> head_weight{nullptr, 0, D};  ///< [C, d]: row c, a_j(t + c) of token j
  WeightView<X, 1> head_bias{nullptr, 0, 1};    ///< [C]
  WeightView<X, 1> head_ensemble_decay{nullptr, 0, 1};  ///< [1] when C > 1: w_k = exp(−decay·k)
  WeightView<J, 1> q_mean{nullptr}, q_std{nullptr};  ///< rad
  WeightView<J, 1> a_mean{nullptr}, a_std{nullptr};  ///< rad per step
  WeightView<J, 1> r_mean{nullptr}, r_std{nullptr};  ///< rad
  WeightView<J, X> centroids{nullptr, J, 0};  ///< [J, M·K], column m*K + k: key pose k of movement m, rad
  /// law.gain: the runtime's only law on top of the network, gain_j · r_j added to a reference-mode
  /// model's action (the first-order servo inversion, docs/policy.md); all 0 in autonomous models.
  WeightView<J, 1> law_gain{nullptr};
  Conditioning conditioning = Conditioning::kReference;
  /// The kernels stepPolicy runs these weights with (nao/policy_kernels/dispatch.hpp), chosen by
  /// the binder (bestPolicyKernel() unless told otherwise) and checked against the CPU there;
  /// every kernel gives the same bits. kSse, which every CPU runs, until bound. Change it only
  /// to a kernel policyKernelSupported accepts (setPolicyKernel checks).
  PolicyKernel kernel = PolicyKernel::kSse;
  /// w_k / Σ w of the temporal ensemble, for the chunk made k ticks ago, once k + 1 chunks
  /// exist (row k of the triangle: ensemble_weight[n − 1][k] with n = min(ticks, C) chunks);
  /// made at bind time from head.ensemble_decay.
  std::array<std::array<float, kPolicyMaxChunk>, kPolicyMaxChunk> ensemble_weight{};
  /// The bytes the views read, kept alive by every copy of these weights; null: the caller's
  /// (pointers it passed, the compiled-in image in .rodata).
  std::shared_ptr<const void> storage;
};

namespace detail {


/// One view of PolicyWeights as the binder sees it.
struct WeightSlot {
  std::string name;  ///< manifest name
  int rows;          ///< Eigen shape of the view; Eigen::Dynamic: the tensor's
  int cols;
  bool matrix;       ///< the view has an int8 / packed companion (QuantView): TensorRole::kMatrix
  void* view;        ///< the WeightView<rows, cols> to point at the tensor
  void (*rebind)(void* view, const float* data, long rows, long cols);
};

template <int R, int C>
void rebindView(void* view, const float* data, long rows, long cols) {
  // Eigen's documented way to change the array a Map views.
  if constexpr (R == Eigen::Dynamic || C == Eigen::Dynamic)
    new (view) WeightView<R, C>(data, rows, cols);
  else
    new (view) WeightView<R, C>(data);
  (void)rows;
  (void)cols;
}

/// The table's sizes for the views of `w` (its compiled dimensions, its bound table sizes).
template <class Dims>
constexpr PolicySizes policySizes(int movements, int clusters, int max_steps, int chunk) {
  PolicySizes a;
  a.d_model = Dims::kDModel;
  a.heads = Dims::kHeads;
  a.encoder_layers = Dims::kEncoderLayers;
  a.decoder_layers = Dims::kDecoderLayers;
  a.tokens = Dims::kTokens;
  a.features = Dims::kFeatures;
  a.window = Dims::kWindow;
  a.ffn_hidden = {Dims::kFfn0, Dims::kFfn1, Dims::kFfn2};
  a.movements = movements;
  a.clusters = clusters;
  a.max_steps = max_steps;
  a.chunk = chunk;
  return a;
}

/// Calls f(ViewName, WeightView<R, C>&) for every view of `w`, in the order of policyManifest
/// (the one table, walkPolicyManifest), and for a matrix of role TensorRole::kMatrix
/// f(ViewName, WeightView<Out, In>&, QuantView<Out, In>&) with its int8 and packed companion.
/// No allocation unless f allocates.
template <class Dims, class F>
void visitWeightViews(PolicyWeights<Dims>& w, F&& f) {
  walkPolicyManifest(policySizes<Dims>(w.movements, w.clusters, w.max_steps, w.chunk),
                     [&](const ViewName& name, const ManifestShape&, TensorRole, auto at) {
                       at(w, [&](auto& view, auto&... quant) { f(name, view, quant...); });
                     });
}

/// Counts the table's entries (a constexpr sink).
struct ViewCounter {
  std::size_t n = 0;
  template <class At>
  constexpr void operator()(const ViewName&, const ManifestShape&, TensorRole, const At&) {
    ++n;
  }
};

/// Number of views of a PolicyWeights<Dims> with chunk `chunk` (= entries of its policyManifest).
template <class Dims>
constexpr std::size_t policyViewCount(int chunk) {
  ViewCounter c;
  walkPolicyManifest(policySizes<Dims>(1, 1, 1, chunk), c);
  return c.n;
}

/// Every view of `w` with its manifest name (binding matches by name).
template <class Dims>
std::vector<WeightSlot> weightSlots(PolicyWeights<Dims>& w) {
  std::vector<WeightSlot> s;
  visitWeightViews(w, [&s](const ViewName& name, auto& view, auto&... quant) {
    using View = std::remove_reference_t<decltype(view)>;
    s.push_back({name.str(), View::RowsAtCompileTime, View::ColsAtCompileTime, sizeof...(quant) == 1, &view,
                 &rebindView<View::RowsAtCompileTime, View::ColsAtCompileTime>});
  });
  return s;
}

/// Points every slot at its manifest tensor, matched by name; checks that the manifest and the
/// slots name the same tensors with the same shapes, and that exactly the kMatrix tensors have
/// an int8 / packed companion. Throws std::invalid_argument naming the tensor
/// (runtime/core/src/policy.cpp).
void bindWeightSlots(const std::vector<WeightSlot>& slots, const std::vector<TensorSpec>& manifest,
                     const float* const* tensors, std::size_t count);

/// Throws std::invalid_argument describing both architectures if they differ.
void requireArch(const PolicyArch& compiled, const PolicyArch& given);

/// Calls f(const WeightView<Out, In>&, QuantView<Out, In>&) for every matrix of role
/// TensorRole::kMatrix, in manifest order: the order of the int8 and packed blobs
/// (codegen/src/quantize.cpp walks the manifest's kMatrix entries).
template <class Dims, class F>
void visitQuantViews(PolicyWeights<Dims>& w, F&& f) {
  visitWeightViews(w, [&f](const ViewName&, auto& view, auto&... quant) {
    if constexpr (sizeof...(quant) == 1) f(view, quant...);
  });
}

/// Bytes of a matrix's section in the int8 blob: Out·In weight bytes, then Out scales, each
/// padded to kQuantAlignment.
inline constexpr std::size_t kQuantAlignment = 64;
constexpr std::size_t quantPad(std::size_t n) { return (n + kQuantAlignment - 1) / kQuantAlignment * kQuantAlignment; }
constexpr std::size_t quantSectionBytes(std::size_t out, std::size_t in) {
  return quantPad(out * in) + quantPad(out * sizeof(float));
}

}  // namespace detail

/// Throws std::invalid_argument (naming both) if `arch`, e.g. the header of a model.bin, does
/// not have the compiled Dims' computation (another FFN depth included), is unusable
/// (archProblem), or has a chunk beyond the runtime's (kPolicyMaxChunk). The table sizes (movements, key poses, step rows) may be anything. Configure
/// time.
template <class Dims>
void checkPolicyArch(const PolicyArch& arch) {
  detail::requireArch(Dims::arch(), arch);
}

}  // namespace nao
