// The imitation policy's forward pass (docs/policy.md): a pre-layer-norm encoder-decoder
// Transformer over time x body part (docs/policy.md), streamed one tick at a time as fixed-size
// float Eigen code.
//
// Model/data split: PolicyWeights<Dims> (policy_weights.hpp) holds fixed-size
// Eigen::Map views of the manifest tensors; PolicyWorkspace<Dims> holds every intermediate, the
// key/value rings of the last W ticks, the chunks of the last C ticks and the attention record.
// stepPolicy reads the first, writes the second, and allocates nothing, throws nothing, does no I/O.
//
// Tokens: (τ, j) = joint j at tick τ. The encoder is causal in time with a sliding window: in
// every layer token (τ, j) attends to the tokens (τ', j') of ticks τ − W < τ' ≤ τ, every joint,
// with a learned per-head bias of the age τ − τ'. Its keys and values never change once made,
// so the runtime keeps them in a ring of W ticks per layer and computes only the new tick's J
// tokens per step. The decoder's J action tokens (masked proximal → distal) cross-attend to the
// encoder memory of the same window, with its own age bias; the memory's cross keys/values are
// ringed the same way. Training (toolchain/src/torch) runs whole sequences with the equivalent
// mask; tests/test_torch_parity.cpp holds the two to float tolerance over rollouts longer than W.
//
// Notation: d = d_model, J = 5 tokens per tick (robot joints, proximal to distal), H heads,
// d_h = d / H, W window (ticks), M movements, K key poses per movement, S step-embedding rows.
// Layout: a manifest matrix [in, out] row-major is the same bytes as a column-major Eigen
// [out, in] matrix, so y = W x with W the view (the docs' row-vector `x W`). Activations are
// [d, J] matrices, one column per token of the new tick, and a product W X runs over W once for
// all J tokens: the weights (24 MB for the paper config) are nearly all of the memory traffic.
#pragma once

#include "nao/policy_config.hpp"
#include "nao/policy_kernels.hpp"
#include "nao/policy_weights.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace nao {

/// Everything stepPolicy writes: intermediates, the key/value rings of the last W ticks and the
/// attention record of the last step. About 1 MB for the paper dimensions; build it once at
/// configure time (makePolicyWorkspace), not as a stack object in the loop, and clear it with
/// resetPolicyStream before a new rollout.
template <class Dims>
struct PolicyWorkspace {
  static constexpr int D = Dims::kDModel, J = Dims::kTokens, H = Dims::kHeads, W = Dims::kWindow;
  static constexpr int Dh = Dims::kHeadDim, LE = Dims::kEncoderLayers, LD = Dims::kDecoderLayers;
  static constexpr int N = Dims::kMemory;
  static constexpr std::size_t kCacheLine = 64;
  using Tokens = Eigen::Matrix<float, D, J>;  ///< one column per token of the new tick
  using Ring = Eigen::Matrix<float, D, N>;    ///< column slot*J + j: token j of the tick in `slot`
  /// Rows of a key ring: N padded to whole passes of the score kernels (the extra rows are
  /// scored and ignored).
  static constexpr int kKeyRows = (N + detail::kKeyRowBlock - 1) / detail::kKeyRowBlock * detail::kKeyRowBlock;
  /// A key ring, transposed: row slot*J + j is token j of the tick in `slot`, so column d holds
  /// dimension d of every key (the lanes of detail::windowScores).
  using KeyRing = Eigen::Matrix<float, kKeyRows, D>;
  using JointVec = Eigen::Matrix<float, J, 1>;

  // Stream position: ticks since resetPolicyStream; the new tick goes to slot ticks % W.
  std::int64_t ticks = 0;

  // Inputs as used: normalised features, clamped movement and step.
  JointVec qn = JointVec::Zero(), an = JointVec::Zero(), rn = JointVec::Zero();
  int movement = 0;
  int step = 0;
  /// The run's code, added to every encoder token (a model trained with a per-run latent: the
  /// code of the demonstration the run follows, setPolicyRunCode; zero: the latent's prior mean).
  /// Kept by resetPolicyStream.
  Eigen::Matrix<float, D, 1> run_code = Eigen::Matrix<float, D, 1>::Zero();

  Tokens x = Tokens::Zero();       ///< encoder residual stream of the new tick
  Tokens memory = Tokens::Zero();  ///< LN_enc(x): the new tick's memory tokens
  Tokens y = Tokens::Zero();       ///< decoder residual stream
  Tokens h = Tokens::Zero();       ///< layer-norm output (sublayer input)
  Tokens q = Tokens::Zero(), k = Tokens::Zero(), v = Tokens::Zero();  ///< attention Q, K, V
  Tokens o = Tokens::Zero();       ///< heads' outputs [O_0 ... O_{H-1}] before Wo
  Tokens out = Tokens::Zero();     ///< sublayer output before the residual add
  Eigen::Matrix<float, Dims::kFfn0, J> f0 = Eigen::Matrix<float, Dims::kFfn0, J>::Zero();
  Eigen::Matrix<float, Dims::kFfn1, J> f1 = Eigen::Matrix<float, Dims::kFfn1, J>::Zero();
  Eigen::Matrix<float, Dims::kFfn2, J> f2 = Eigen::Matrix<float, Dims::kFfn2, J>::Zero();
  Eigen::Matrix<float, Dh, J> v_head = Eigen::Matrix<float, Dh, J>::Zero();  ///< V_h, contiguous

  // Key/value rings: keys and values of every encoder layer's self-attention and every decoder
  // layer's cross-attention, for the tokens of the last W ticks. On cache-line boundaries
  // (kCacheLine): Eigen aligns them to 16 bytes only, and then every zmm load of the window
  // kernels spans two lines (the paper model's scores ran at half speed).
  alignas(kCacheLine) std::array<KeyRing, LE> enc_k{};
  alignas(kCacheLine) std::array<Ring, LE> enc_v{};
  alignas(kCacheLine) std::array<KeyRing, LD> cross_k{};
  alignas(kCacheLine) std::array<Ring, LD> cross_v{};
  /// f_h(M) = Wo_h V_h of the last decoder layer's cross-attention per memory token (norm score).
  alignas(kCacheLine) std::array<Ring, H> f_ring{};
  /// α of the latest attention over the window (scratch): [h][query i][age * J + j].
  alignas(kCacheLine) float alpha[H][J][N] = {};

  /// Attention record. cross[l][h][i][j]: α of decoder layer l's cross-attention, head h,
  /// action token i (query), summed over the window's ticks for body part j; rows sum to 1.
  float cross[LD][H][J][J] = {};
  /// Raw cross-attention mass of body part j in the last decoder layer: mean over heads and
  /// action tokens of cross[LD-1][h][i][j] (sums to 1 over j).
  JointVec mass = JointVec::Zero();
  /// Norm-based score of body part j in the last decoder layer's cross-attention (Kobayashi et
  /// al. 2020), summed over the window: Σ_i Σ_τ ‖Σ_h α_h[i][(τ, j)] f_h(M_{τ,j})‖ (docs/policy.md).
  JointVec score = JointVec::Zero();
  /// Temporal profile: mass of the last decoder layer's cross-attention per age (0 = this
  /// tick), mean over heads and action tokens; sums to 1 over the ages in the window so far.
  Eigen::Matrix<float, W, 1> age_profile = Eigen::Matrix<float, W, 1>::Zero();
  /// Column i: the last decoder layer's cross-attention output of action token i (after Wo, bo,
  /// before the residual add).
  Tokens cross_out = Tokens::Zero();

  /// The head's chunk of this tick, rad: column c is a(t + c) (the first C columns are used).
  using Chunk = Eigen::Matrix<float, J, kPolicyMaxChunk>;
  Chunk chunk = Chunk::Zero();
  /// The chunks of the last C ticks: the one made at tick τ in slot τ % C.
  std::array<Chunk, kPolicyMaxChunk> chunk_ring{};
  /// The network's action a(t), rad: the temporal ensemble of the chunks' entries for this tick.
  JointVec net_action = JointVec::Zero();
  JointVec action = JointVec::Zero();    ///< actions a(t), rad per step: net_action plus the model's law
};

/// A heap-allocated workspace (configure time).
template <class Dims>
std::unique_ptr<PolicyWorkspace<Dims>> makePolicyWorkspace() {
  return std::make_unique<PolicyWorkspace<Dims>>();
}

/// One step's inputs, joint order (RShoulderPitch .. RWristYaw).
struct PolicyInput {
  Eigen::Matrix<float, 5, 1> q = Eigen::Matrix<float, 5, 1>::Zero();       ///< joint state, rad
  Eigen::Matrix<float, 5, 1> a_prev = Eigen::Matrix<float, 5, 1>::Zero();  ///< previous action, rad
  Eigen::Matrix<float, 5, 1> r = Eigen::Matrix<float, 5, 1>::Zero();  ///< snapped reference, rad (ignored in autonomous mode)
  int movement = 0;  ///< movement index (sorted names); clamped to 0..M-1
  int step = 0;      ///< step index; clamped to 0..S-1
};

namespace detail {

/// Y = W X + b (ReLU if kRelu) with the matrix's int8 copy if it has one, else in fp32 from
/// its packed copy if it has one (the same bits), else from the view.
template <bool kRelu, int Out, int In, int J>
inline void affine(PolicyKernel kernel, const WeightView<Out, In>& W, const QuantView<Out, In>& Wq,
                   const WeightView<Out, 1>& b, const Eigen::Matrix<float, In, J>& X, Eigen::Matrix<float, Out, J>& Y) {
  if constexpr (In % 2 == 0 && In <= kInt8MaxIn) {  // else no int8 copy can exist (bindQuantizedWeights)
    if (Wq.w != nullptr) {
      affineTokensInt8<Out, In, J, kRelu>(kernel, Wq.w, Wq.scale, b.data(), X.data(), Y.data());
      return;
    }
  }
  if constexpr (packedShape(Out, In)) {  // else no packed copy can exist (bindPackedWeights)
    if (Wq.packed != nullptr) {
      affineTokensPacked<Out, In, J, kRelu>(kernel, Wq.packed, b.data(), X.data(), Y.data());
      return;
    }
  }
  affineTokens<Out, In, J, kRelu>(kernel, W.data(), b.data(), X.data(), Y.data());
}

/// out(:, j) = LN(x(:, j)): biased variance over d, eps 1e-5.
template <class Dims>
inline void layerNorm(const typename PolicyWorkspace<Dims>::Tokens& x, const LayerNormWeights<Dims>& n,
                      typename PolicyWorkspace<Dims>::Tokens& out) {
  constexpr float kInvD = 1.0f / static_cast<float>(Dims::kDModel);
  for (int j = 0; j < Dims::kTokens; ++j) {
    const float mean = x.col(j).sum() * kInvD;
    const float var = (x.col(j).array() - mean).square().sum() * kInvD;
    const float inv_std = 1.0f / std::sqrt(var + 1e-5f);
    out.col(j) = ((x.col(j).array() - mean) * inv_std * n.gain.array() + n.bias.array()).matrix();
  }
}

/// ws.out = causal self-attention of the J new action tokens (query i sees tokens 0..i), from
/// ws.h; ws.q, ws.k, ws.v, ws.o hold the intermediates afterwards.
template <class Dims>
inline void jointSelfAttention(PolicyKernel kernel, const AttentionWeights<Dims>& A, PolicyWorkspace<Dims>& ws) {
  constexpr int J = Dims::kTokens, Dh = Dims::kHeadDim;
  affine<false>(kernel, A.wq, A.wq8, A.bq, ws.h, ws.q);
  affine<false>(kernel, A.wk, A.wk8, A.bk, ws.h, ws.k);
  affine<false>(kernel, A.wv, A.wv8, A.bv, ws.h, ws.v);
  const float scale = 1.0f / std::sqrt(static_cast<float>(Dh));
  for (int hd = 0; hd < Dims::kHeads; ++hd) {
    const int c0 = hd * Dh;
    for (int i = 0; i < J; ++i) {
      // Masked keys are skipped, not added as exp(-inf) = 0: query i never reads keys > i.
      float s[J];
      float s_max = -std::numeric_limits<float>::infinity();
      for (int j = 0; j <= i; ++j) {
        s[j] = ws.q.col(i).template segment<Dh>(c0).dot(ws.k.col(j).template segment<Dh>(c0)) * scale;
        s_max = std::max(s_max, s[j]);
      }
      float sum = 0.0f;
      for (int j = 0; j <= i; ++j) {
        s[j] = std::exp(s[j] - s_max);
        sum += s[j];
      }
      ws.o.col(i).template segment<Dh>(c0).setZero();
      for (int j = 0; j <= i; ++j) ws.o.col(i).template segment<Dh>(c0) += (s[j] / sum) * ws.v.col(j).template segment<Dh>(c0);
    }
  }
  affine<false>(kernel, A.wo, A.wo8, A.bo, ws.o, ws.out);
}

/// α of J queries over the last n ticks (alpha[i][age·J + j]) as if the keys of the body parts
/// in `masked` (bit j: part j) had logits −∞: theirs set to 0, the others rescaled to sum to 1
/// again - the softmax over the remaining keys, exactly. A query whose whole mass was masked
/// keeps zeros (its output is then 0).
template <int J, int N>
inline void maskBodyParts(float (*alpha)[N], int n, unsigned masked) {
  for (int i = 0; i < J; ++i) {
    float keep = 0.0f;
    for (int age = 0; age < n; ++age)
      for (int j = 0; j < J; ++j)
        if (((masked >> j) & 1u) == 0) keep += alpha[i][age * J + j];
    const float inv = keep > 0.0f ? 1.0f / keep : 0.0f;
    for (int age = 0; age < n; ++age)
      for (int j = 0; j < J; ++j) {
        float& a = alpha[i][age * J + j];
        a = ((masked >> j) & 1u) != 0 ? 0.0f : a * inv;
      }
  }
}

/// Attention of the J queries in ws.q over the tokens of the last `n` ticks in the rings K
/// (keys, transposed) and V (n = min(ticks, W), the newest tick in `slot`), with the age bias:
/// ws.o (before Wo) and α in ws.alpha[h][i][age * J + j]. The softmax and the value sum visit
/// the keys newest first, so the sums do not depend on where the ring happens to start. The
/// scores are those of Eigen's per-key dot, bit for bit (detail::windowScores). A head's J
/// queries go through each pass side by side: every query's maximum, sum and value sum still
/// run over its keys in order (the same bits as one query at a time), but the J chains of
/// dependent operations overlap instead of waiting on each other.
/// `masked`: bit j set, the keys of body part j are left out (their logits −∞), every tick of
/// the window (maskBodyParts); 0 in a normal step.
template <class Dims>
inline void windowAttention(PolicyKernel kernel, const TemporalAttentionWeights<Dims>& A,
                            const typename PolicyWorkspace<Dims>::KeyRing& K,
                            const typename PolicyWorkspace<Dims>::Ring& V, int slot, int n, PolicyWorkspace<Dims>& ws,
                            unsigned masked = 0) {
  constexpr int J = Dims::kTokens, Dh = Dims::kHeadDim, W = Dims::kWindow, N = Dims::kMemory, D = Dims::kDModel;
  constexpr int NP = PolicyWorkspace<Dims>::kKeyRows;
  const float scale = 1.0f / std::sqrt(static_cast<float>(Dh));
  // Slots 0 .. n−1 hold the window (n < W only before the ring first wraps): keys 0 .. n·J−1.
  const int keys = n * J;
  const int rows = (keys + kKeyRowBlock - 1) / kKeyRowBlock * kKeyRowBlock;
  alignas(64) float raw[J][NP];  // scores by ring row, per query
  for (int hd = 0; hd < Dims::kHeads; ++hd) {
    const int c0 = hd * Dh;
    if constexpr (kWindowKernelExact<Dh>) {
      windowScoresQueries<Dh, NP, J>(kernel, ws.q.data() + c0, D, K.data() + static_cast<std::ptrdiff_t>(c0) * NP,
                                     rows, scale, raw[0], NP);
    } else {
      for (int i = 0; i < J; ++i) {
        const float* q = ws.q.col(i).data() + c0;
        for (int r = 0; r < keys; ++r) {
          float dot = 0.0f;
          for (int d = 0; d < Dh; ++d) dot += q[d] * K(r, c0 + d);
          raw[i][r] = dot * scale;
        }
      }
    }
    float (*s)[N] = ws.alpha[hd];
    windowSoftmax<J, W, NP, N>(kernel, raw[0], A.age_bias.col(hd).data(), slot, n, s[0]);
    if (masked != 0) maskBodyParts<J, N>(s, n, masked);
    windowValuesQueries<Dh, J, W, J>(kernel, s[0], N, V.data() + c0, D, slot, n, ws.o.data() + c0, D);
  }
}

/// The record of the last decoder layer's cross-attention (α in ws.alpha over the last n
/// ticks): ws.mass, ws.age_profile, ws.score (norm-based, from ws.f_ring).
template <class Dims>
inline void crossAttentionRecord(PolicyKernel kernel, int slot, int n, PolicyWorkspace<Dims>& ws) {
  constexpr int J = Dims::kTokens, H = Dims::kHeads, W = Dims::kWindow;
  constexpr float kInv = 1.0f / static_cast<float>(H * J);
  // Summed in locals (in the same order): through ws the compiler kept every partial sum in
  // memory, a store-to-load chain per add.
  float mass[J] = {}, profile[W] = {};
  for (int hd = 0; hd < H; ++hd)
    for (int i = 0; i < J; ++i)
      for (int age = 0; age < n; ++age)
        for (int j = 0; j < J; ++j) {
          const float a = ws.alpha[hd][i][age * J + j] * kInv;
          mass[j] += a;
          profile[age] += a;
        }
  for (int j = 0; j < J; ++j) ws.mass[j] = mass[j];
  for (int age = 0; age < W; ++age) ws.age_profile[age] = profile[age];
  // ‖Σ_h α_h f_h‖ per query, key tick and joint (detail::headSumNorm: one summation order at
  // every lane width), all J queries of a key at once, then summed query by query as before.
  float norm[W][J][J];  // [age][key joint j][query i]
  for (int age = 0; age < n; ++age) {
    const int base = ((slot - age + W) % W) * J;
    for (int j = 0; j < J; ++j) {
      float a[J * H];
      const float* f[H];
      for (int hd = 0; hd < H; ++hd) {
        f[hd] = ws.f_ring[static_cast<std::size_t>(hd)].col(base + j).data();
        for (int i = 0; i < J; ++i) a[i * H + hd] = ws.alpha[hd][i][age * J + j];
      }
      headSumNorms<Dims::kDModel, H, J>(kernel, a, f, norm[age][j]);
    }
  }
  float score[J] = {};
  for (int i = 0; i < J; ++i)
    for (int age = 0; age < n; ++age)
      for (int j = 0; j < J; ++j) score[j] += norm[age][j][i];
  for (int j = 0; j < J; ++j) ws.score[j] = score[j];
}

template <class Dims>
inline void feedForward(PolicyKernel kernel, const FfnWeights<Dims>& F, PolicyWorkspace<Dims>& ws) {
  affine<true>(kernel, F.w0, F.w0q, F.b0, ws.h, ws.f0);
  affine<true>(kernel, F.w1, F.w1q, F.b1, ws.f0, ws.f1);
  affine<true>(kernel, F.w2, F.w2q, F.b2, ws.f1, ws.f2);
  affine<false>(kernel, F.w3, F.w3q, F.b3, ws.f2, ws.out);
}

}  // namespace detail

namespace detail {

/// The table and head sizes of `arch` into `w`, so the visitors walk its views.
template <class Dims>
void setPolicySizes(PolicyWeights<Dims>& w, const PolicyArch& arch, Conditioning c, PolicyKernel kernel) noexcept {
  w.movements = arch.movements;
  w.clusters = arch.clusters;
  w.max_steps = arch.max_steps;
  w.chunk = arch.chunk;
  w.conditioning = c;
  w.kernel = kernel;
}

/// The normalised temporal-ensemble weights from head.ensemble_decay (equal weights for C = 1).
template <class Dims>
void setEnsembleWeights(PolicyWeights<Dims>& w) noexcept {
  const float decay = w.chunk > 1 ? w.head_ensemble_decay(0) : 0.0f;
  for (int n = 1; n <= w.chunk; ++n) {
    double sum = 0.0;
    for (int k = 0; k < n; ++k) sum += std::exp(-static_cast<double>(decay) * k);
    for (int k = 0; k < n; ++k)
      w.ensemble_weight[static_cast<std::size_t>(n - 1)][static_cast<std::size_t>(k)] =
          static_cast<float>(std::exp(-static_cast<double>(decay) * k) / sum);
  }
}

}  // namespace detail

/// Binds the views of a PolicyWeights to tensor data. Configure time (allocates).
/// @param tensors tensors[i] points to the floats of entry i of policyManifest(arch), row-major
///                as in model.bin; the data must outlive the returned weights
/// @param count   number of pointers; must equal the manifest size
/// @param arch    the model's architecture (checkPolicyArch<Dims>)
/// @param c       the conditioning mode of the model
/// @param kernel  the kernels stepPolicy runs these weights with (PolicyWeights::kernel; every
///                kernel gives the same bits): by default the best this CPU runs
/// @throws std::invalid_argument on another architecture, a wrong count, a null pointer or a
///         kernel this CPU does not run (requirePolicyKernel); a manifest entry without a view of
///         the same name and shape (a programming error) is reported the same way.
template <class Dims>
PolicyWeights<Dims> bindPolicyWeights(const float* const* tensors, std::size_t count, const PolicyArch& arch,
                                      Conditioning c, PolicyKernel kernel = bestPolicyKernel()) {
  requirePolicyKernel(kernel);
  checkPolicyArch<Dims>(arch);
  PolicyWeights<Dims> w;
  detail::setPolicySizes(w, arch, c, kernel);
  // By name against the manifest itself, so its order can change without a silent mismatch.
  detail::bindWeightSlots(detail::weightSlots(w), policyManifest(arch), tensors, count);
  detail::setEnsembleWeights(w);
  return w;
}

/// Binds the views of a PolicyWeights to a model.bin image in memory (the compiled-in bytes in
/// .rodata): entry i of policyManifest(arch) at base + offsets[i], its view of extent
/// extents[i] (codegen's constexpr kTensorOffsets and kTensorExtents, made from the manifest
/// when the code was generated; mappedModelFile checks them against it once). No name lookup,
/// no copy, no allocation; the image must outlive the weights. `arch` must pass
/// checkPolicyArch<Dims> (codegen's does). `kernel` as for bindPolicyWeights.
/// @throws std::invalid_argument for a kernel this CPU does not run (requirePolicyKernel); with
///         the default kernel, never.
template <class Dims>
PolicyWeights<Dims> bindPolicyWeightsAt(const std::uint8_t* base, const std::uint64_t* offsets,
                                        const TensorExtent* extents, const PolicyArch& arch, Conditioning c,
                                        PolicyKernel kernel = bestPolicyKernel()) {
  requirePolicyKernel(kernel);
  PolicyWeights<Dims> w;
  detail::setPolicySizes(w, arch, c, kernel);
  std::size_t i = 0;
  detail::visitWeightViews(w, [&](const detail::ViewName&, auto& view, auto&...) {
    using View = std::remove_reference_t<decltype(view)>;
    const float* data = reinterpret_cast<const float*>(base + offsets[i]);
    const TensorExtent e = extents[i++];
    // A flat view (one dynamic column) takes the tensor whole.
    if constexpr (View::RowsAtCompileTime == Eigen::Dynamic && View::ColsAtCompileTime == 1)
      new (&view) View(data, static_cast<long>(e.rows * e.cols), 1);
    else if constexpr (View::RowsAtCompileTime == Eigen::Dynamic || View::ColsAtCompileTime == Eigen::Dynamic)
      new (&view) View(data, static_cast<long>(e.rows), static_cast<long>(e.cols));
    else
      new (&view) View(data);
  });
  detail::setEnsembleWeights(w);
  return w;
}

/// Runs `w` with `kernel` from now on (the same bits, another speed): tests and benchmarks that
/// compare the kernels on one binding. Configure time.
/// @throws std::invalid_argument, w unchanged, for a kernel this CPU does not run
template <class Dims>
void setPolicyKernel(PolicyWeights<Dims>& w, PolicyKernel kernel) {
  requirePolicyKernel(kernel);
  w.kernel = kernel;
}

/// True if every int8 matrix of a Dims model has an even input size of at most kInt8MaxIn
/// (d_model, the FFN widths and the head size; quantizeModelInt8 refuses other models).
template <class Dims>
constexpr bool int8Supported() {
  constexpr auto ok = [](int in) { return in % 2 == 0 && in <= detail::kInt8MaxIn; };
  return ok(Dims::kDModel) && ok(Dims::kFfn0) && ok(Dims::kFfn1) && ok(Dims::kFfn2) && ok(Dims::kHeadDim);
}

/// Bytes of the int8 blob of a Dims model (quantizeModelInt8's output for its architecture).
template <class Dims>
constexpr std::size_t quantizedPolicyBytes() {
  constexpr std::size_t D = Dims::kDModel, F0 = Dims::kFfn0, F1 = Dims::kFfn1, F2 = Dims::kFfn2;
  constexpr std::size_t attention = 4 * detail::quantSectionBytes(D, D);
  constexpr std::size_t ffn = detail::quantSectionBytes(F0, D) + detail::quantSectionBytes(F1, F0) +
                              detail::quantSectionBytes(F2, F1) + detail::quantSectionBytes(D, F2);
  return Dims::kEncoderLayers * (attention + ffn) + Dims::kDecoderLayers * (2 * attention + ffn);
}

/// Points the int8 views of `w` into `blob` (quantizeModelInt8's layout, 64-byte aligned, at
/// least quantizedPolicyBytes<Dims>() bytes): from now on stepPolicy runs those matrices in int8
/// (any packed copy dropped). The fp32 views stay bound (biases, norms, embeddings and the head
/// are fp32 in both). No allocation; the blob must outlive the weights.
template <class Dims>
void bindQuantizedWeights(PolicyWeights<Dims>& w, const std::uint8_t* blob) noexcept {
  static_assert(int8Supported<Dims>(), "int8 weights need even input sizes of at most 512");
  std::size_t off = 0;
  detail::visitQuantViews(w, [&](const auto&, auto& q) {
    using Q = std::remove_reference_t<decltype(q)>;
    const std::size_t out = Q::kOut, in = Q::kIn;
    q = {};  // drops any packed copy
    q.w = reinterpret_cast<const std::int8_t*>(blob + off);
    q.scale = reinterpret_cast<const float*>(blob + off + detail::quantPad(out * in));
    off += detail::quantSectionBytes(out, in);
  });
}

/// Drops the int8 and packed views: every matrix runs from its fp32 view again.
template <class Dims>
void unbindQuantizedWeights(PolicyWeights<Dims>& w) noexcept {
  detail::visitQuantViews(w, [](const auto&, auto& q) { q = {}; });
}

/// True if `w` runs its matrices in int8 (bindQuantizedWeights).
template <class Dims>
bool usesInt8(const PolicyWeights<Dims>& w) noexcept {
  return w.enc[0].attn.wq8.w != nullptr;
}

/// True if every matrix visitQuantViews visits has a packed fp32 copy (policy_kernels.hpp
/// packedShape: out a multiple of 32, in of 16; the paper and small configurations do).
template <class Dims>
constexpr bool packedSupported() {
  using detail::packedShape;
  constexpr int D = Dims::kDModel, F0 = Dims::kFfn0, F1 = Dims::kFfn1, F2 = Dims::kFfn2;
  return packedShape(D, D) && packedShape(F0, D) && packedShape(F1, F0) && packedShape(F2, F1) && packedShape(D, F2);
}

/// Bytes of the packed fp32 blob of a Dims model: every visitQuantViews matrix, in that order,
/// in the packed layout (no padding: each is a multiple of 2 KB).
template <class Dims>
constexpr std::size_t packedPolicyBytes() {
  constexpr std::size_t D = Dims::kDModel, F0 = Dims::kFfn0, F1 = Dims::kFfn1, F2 = Dims::kFfn2;
  constexpr std::size_t attention = 4 * D * D, ffn = F0 * D + F1 * F0 + F2 * F1 + D * F2;
  return sizeof(float) * (Dims::kEncoderLayers * (attention + ffn) + Dims::kDecoderLayers * (2 * attention + ffn));
}

/// Points the packed views of `w` into `blob` (packModelFp32's layout, 64-byte aligned, at
/// least packedPolicyBytes<Dims>() bytes): from now on stepPolicy reads those matrices from it,
/// with the same bits. Drops any int8 copy. No allocation; the blob must outlive the weights.
template <class Dims>
void bindPackedWeights(PolicyWeights<Dims>& w, const std::uint8_t* blob) noexcept {
  static_assert(packedSupported<Dims>(), "packed fp32 weights need out % 32 == 0 and in % 16 == 0");
  std::size_t off = 0;
  detail::visitQuantViews(w, [&](const auto&, auto& q) {
    using Q = std::remove_reference_t<decltype(q)>;
    q = {};
    q.packed = reinterpret_cast<const float*>(blob + off);
    off += sizeof(float) * Q::kOut * Q::kIn;
  });
}

/// True if `w` reads its matrices from a packed fp32 copy (bindPackedWeights).
template <class Dims>
bool usesPacked(const PolicyWeights<Dims>& w) noexcept {
  return w.enc[0].attn.wq8.packed != nullptr;
}

namespace detail {
/// One load per 64-byte line of [p, p + bytes) (and of its last byte), added to `sink` so the
/// loads cannot be dropped. Returns bytes.
inline std::size_t touchLines(const void* p, std::size_t bytes, std::uint64_t& sink) noexcept {
  const auto* c = static_cast<const volatile unsigned char*>(p);
  std::uint64_t s = 0;
  for (std::size_t i = 0; i < bytes; i += 64) s += c[i];
  if (bytes > 0) s += c[bytes - 1];
  sink += s;
  return bytes;
}

/// Touches a matrix's int8 bytes and scales, or its packed copy, into `bytes`; false if it has
/// neither (the step reads its fp32 view).
template <class Q>
bool touchCopy(const Q& q, std::size_t& bytes, std::uint64_t& sink) noexcept {
  const std::size_t n = static_cast<std::size_t>(Q::kOut) * Q::kIn;
  if (q.packed != nullptr) {
    bytes += touchLines(q.packed, n * sizeof(float), sink);
    return true;
  }
  if (q.w == nullptr) return false;
  bytes += touchLines(q.w, n, sink);
  bytes += touchLines(q.scale, static_cast<std::size_t>(Q::kOut) * sizeof(float), sink);
  return true;
}

}  // namespace detail

/// Loads every byte the next stepPolicy reads into the cache: each view stepPolicy uses (a
/// matrix's int8 bytes and scales, or its packed copy, instead of its fp32 view) and the workspace
/// with its key/value rings. For a caller with idle time before a step whose data the cache has
/// lost since the last one: in the 100 ms between two 10 Hz ticks the 24 MB of fp32 weights
/// leave it, and the step then reads them from memory (~2x its hot time here, BM_Policy_Cold_*).
/// nao_rt on LoLA calls it shortly before each tick's packet (docs/lola.md). Adds the bytes'
/// sum to `sink` (meaningless; keep it somewhere) and returns the number of bytes read. No
/// allocation.
template <class Dims>
std::size_t warmPolicy(const PolicyWeights<Dims>& w, const PolicyWorkspace<Dims>& ws, std::uint64_t& sink) noexcept {
  // The visitors take a mutable model (they also bind); nothing here writes through it.
  auto& m = const_cast<PolicyWeights<Dims>&>(w);
  std::size_t bytes = 0;
  detail::visitWeightViews(m, [&](const detail::ViewName&, auto& view, auto&... quant) {
    if (view.data() == nullptr) return;
    // A matrix with an int8 or packed copy is read from that copy, not from its fp32 view.
    if constexpr (sizeof...(quant) == 1)
      if (detail::touchCopy(quant..., bytes, sink)) return;
    bytes += detail::touchLines(view.data(), static_cast<std::size_t>(view.size()) * sizeof(float), sink);
  });
  return bytes + detail::touchLines(&ws, sizeof(ws), sink);
}

/// Starts a new rollout: the window and the chunk ring are empty (the next step is tick 0 and
/// sees only itself). Real-time safe. Ring contents are not cleared: a slot is read only after
/// this stream wrote it.
template <class Dims>
void resetPolicyStream(PolicyWorkspace<Dims>& ws) {
  ws.ticks = 0;
}

/// Sets the run's code (d_model floats, added to every encoder token from the next step on);
/// nullptr: zero. Real-time safe.
template <class Dims>
void setPolicyRunCode(PolicyWorkspace<Dims>& ws, const float* code) {
  if (code == nullptr)
    ws.run_code.setZero();
  else
    ws.run_code = Eigen::Map<const Eigen::Matrix<float, Dims::kDModel, 1>>(code);
}

/// The first part of a policy step (docs/policy.md) at the stream's next tick: normalise the
/// inputs, make the tick's J encoder tokens, run them through the encoder layers attending to the
/// window (their keys/values enter the rings at the tick's slot) and add their memory to the
/// cross-attention rings. Movement and step are clamped to the model's 0..M-1 and 0..S-1 (a
/// caller's index out of range picks the nearest embedding rather than reading out of bounds).
/// rn = 0 in autonomous mode; embed.step is added in both modes (zero in reference-mode files).
/// Does not advance the stream: decodePolicyTick and commitPolicyTick finish the tick
/// (stepPolicy runs all three). Real-time safe.
template <class Dims>
void encodePolicyTick(const PolicyWeights<Dims>& w, PolicyWorkspace<Dims>& ws, const PolicyInput& in) {
  constexpr int J = Dims::kTokens, W = Dims::kWindow, H = Dims::kHeads, Dh = Dims::kHeadDim, D = Dims::kDModel;
  static_assert(J == 5, "PolicyInput carries 5 joints");
  const int slot = static_cast<int>(ws.ticks % W);
  const int n = static_cast<int>(std::min<std::int64_t>(ws.ticks + 1, W));  // ticks in the window
  ws.movement = std::clamp(in.movement, 0, w.movements - 1);
  ws.step = std::clamp(in.step, 0, w.max_steps - 1);
  ws.qn = ((in.q - w.q_mean).array() / w.q_std.array()).matrix();
  ws.an = ((in.a_prev - w.a_mean).array() / w.a_std.array()).matrix();
  if (w.conditioning == Conditioning::kAutonomous)
    ws.rn.setZero();
  else
    ws.rn = ((in.r - w.r_mean).array() / w.r_std.array()).matrix();

  for (int j = 0; j < J; ++j)
    ws.x.col(j) = w.embed_in_weight.col(0) * ws.qn[j] + w.embed_in_weight.col(1) * ws.an[j] +
                  w.embed_in_weight.col(2) * ws.rn[j] + w.embed_in_bias + w.embed_joint_enc.col(j) +
                  w.embed_movement.col(ws.movement) + w.embed_step.col(ws.step) + ws.run_code;

  for (int l = 0; l < Dims::kEncoderLayers; ++l) {
    const EncoderLayerWeights<Dims>& L = w.enc[static_cast<std::size_t>(l)];
    detail::layerNorm<Dims>(ws.x, L.ln1, ws.h);
    detail::affine<false>(w.kernel, L.attn.wq, L.attn.wq8, L.attn.bq, ws.h, ws.q);
    detail::affine<false>(w.kernel, L.attn.wk, L.attn.wk8, L.attn.bk, ws.h, ws.k);
    detail::affine<false>(w.kernel, L.attn.wv, L.attn.wv8, L.attn.bv, ws.h, ws.v);
    ws.enc_k[static_cast<std::size_t>(l)].template middleRows<J>(slot * J) = ws.k.transpose();
    ws.enc_v[static_cast<std::size_t>(l)].template middleCols<J>(slot * J) = ws.v;
    detail::windowAttention<Dims>(w.kernel, L.attn, ws.enc_k[static_cast<std::size_t>(l)],
                                  ws.enc_v[static_cast<std::size_t>(l)], slot, n, ws);
    detail::affine<false>(w.kernel, L.attn.wo, L.attn.wo8, L.attn.bo, ws.o, ws.out);
    ws.x += ws.out;
    detail::layerNorm<Dims>(ws.x, L.ln2, ws.h);
    detail::feedForward<Dims>(w.kernel, L.ffn, ws);
    ws.x += ws.out;
  }
  detail::layerNorm<Dims>(ws.x, w.enc_norm, ws.memory);
  // The new tick's memory tokens enter every decoder layer's cross-attention ring.
  for (int l = 0; l < Dims::kDecoderLayers; ++l) {
    const TemporalAttentionWeights<Dims>& C = w.dec[static_cast<std::size_t>(l)].cross;
    detail::affine<false>(w.kernel, C.wk, C.wk8, C.bk, ws.memory, ws.k);
    detail::affine<false>(w.kernel, C.wv, C.wv8, C.bv, ws.memory, ws.v);
    ws.cross_k[static_cast<std::size_t>(l)].template middleRows<J>(slot * J) = ws.k.transpose();
    ws.cross_v[static_cast<std::size_t>(l)].template middleCols<J>(slot * J) = ws.v;
  }
  {
    // f_h(M) = Wo_h V_h of the last layer (Wo_h: d_h contiguous columns of the view).
    const TemporalAttentionWeights<Dims>& C = w.dec.back().cross;
    for (int hd = 0; hd < H; ++hd) {
      ws.v_head = ws.v.template middleRows<Dh>(hd * Dh);
      Eigen::Matrix<float, D, J>& f = ws.out;  // scratch
      // Columns hd·Dh .. of Wo: the same offset in the int8 copy (pairs of columns, Dh even).
      bool done = false;
      if constexpr (int8Supported<Dims>()) {
        if (C.wo8.w != nullptr) {
          detail::affineTokensInt8<D, Dh, J, false>(w.kernel, C.wo8.w + static_cast<std::ptrdiff_t>(hd) * Dh * D,
                                                    C.wo8.scale, nullptr, ws.v_head.data(), f.data());
          done = true;
        }
      }
      // A head size that is not a multiple of 16 (the small configuration's 8) has no packed
      // slice: it reads the fp32 view (warmPolicy does not load that one).
      if constexpr (detail::packedShape(D, Dh)) {
        if (!done && C.wo8.packed != nullptr) {
          detail::affineTokensPacked<D, Dh, J, false>(w.kernel, C.wo8.packed + static_cast<std::ptrdiff_t>(hd) * Dh * D,
                                                      nullptr, ws.v_head.data(), f.data());
          done = true;
        }
      }
      if (!done)
        detail::affineTokens<D, Dh, J, false>(w.kernel, C.wo.data() + static_cast<std::ptrdiff_t>(hd) * Dh * D,
                                              nullptr, ws.v_head.data(), f.data());
      ws.f_ring[static_cast<std::size_t>(hd)].template middleCols<J>(slot * J) = f;
    }
  }
}

namespace detail {

/// Σ_i a[i] b[i] in index order, one rounding per operation (the head's small products; the same
/// bits on every build).
template <class A, class B>
inline float dotInOrder(const A& a, const B& b, int size) {
  float s = 0.0f;
  for (int i = 0; i < size; ++i) s += a[i] * b[i];
  return s;
}

}  // namespace detail

/// The second part of a step: the decoder over the J action tokens of the tick encodePolicyTick
/// made, and the head, into ws.chunk (rad; column c is a(t + c)). The
/// attention record (ws.cross, ws.mass, ws.score, ws.age_profile, ws.cross_out) is this
/// decoding's. `masked` (bit j: body part j) leaves those parts' keys out of every decoder
/// layer's cross-attention over the whole window (0 in a normal step: no extra work). It is a
/// general cross-attention mask of the step, not an evaluation hook: it acts inside the window
/// softmax, between the scores and the value sum, where no caller can reach, so a decoding
/// without some body parts (the attention ablation, nao/tools/attention_ablation.hpp; a part
/// known to be unseen) needs it here. May run several times per tick (each overwrites what the
/// last wrote). Real-time safe.
template <class Dims>
void decodePolicyTick(const PolicyWeights<Dims>& w, PolicyWorkspace<Dims>& ws, unsigned masked = 0) {
  constexpr int J = Dims::kTokens, W = Dims::kWindow, H = Dims::kHeads, D = Dims::kDModel;
  const int slot = static_cast<int>(ws.ticks % W);
  const int n = static_cast<int>(std::min<std::int64_t>(ws.ticks + 1, W));
  for (int j = 0; j < J; ++j) ws.y.col(j) = w.embed_act_weight * ws.an[j] + w.embed_act_bias + w.embed_joint_dec.col(j);

  for (int l = 0; l < Dims::kDecoderLayers; ++l) {
    const DecoderLayerWeights<Dims>& L = w.dec[static_cast<std::size_t>(l)];
    detail::layerNorm<Dims>(ws.y, L.ln1, ws.h);
    detail::jointSelfAttention<Dims>(w.kernel, L.self, ws);
    ws.y += ws.out;
    detail::layerNorm<Dims>(ws.y, L.ln2, ws.h);
    detail::affine<false>(w.kernel, L.cross.wq, L.cross.wq8, L.cross.bq, ws.h, ws.q);
    detail::windowAttention<Dims>(w.kernel, L.cross, ws.cross_k[static_cast<std::size_t>(l)],
                                  ws.cross_v[static_cast<std::size_t>(l)], slot, n, ws, masked);
    detail::affine<false>(w.kernel, L.cross.wo, L.cross.wo8, L.cross.bo, ws.o, ws.out);
    // Per body part: α summed over the window's ticks, a query's J sums side by side (each over
    // the ages in order, the same bits; one chain of n dependent adds after the other took ~5 µs
    // a step).
    for (int hd = 0; hd < H; ++hd)
      for (int i = 0; i < J; ++i) {
        float sum[J] = {};
        for (int age = 0; age < n; ++age)
          for (int j = 0; j < J; ++j) sum[j] += ws.alpha[hd][i][age * J + j];
        for (int j = 0; j < J; ++j) ws.cross[l][hd][i][j] = sum[j];
      }
    if (l == Dims::kDecoderLayers - 1) {
      ws.cross_out = ws.out;
      detail::crossAttentionRecord<Dims>(w.kernel, slot, n, ws);
    }
    ws.y += ws.out;
    detail::layerNorm<Dims>(ws.y, L.ln3, ws.h);
    detail::feedForward<Dims>(w.kernel, L.ffn, ws);
    ws.y += ws.out;
  }
  detail::layerNorm<Dims>(ws.y, w.dec_norm, ws.h);

  // The head: token j's row of the chunk, normalised units, then rad.
  const int C = w.chunk;
  for (int j = 0; j < J; ++j)
    for (int c = 0; c < C; ++c)
      ws.chunk(j, c) = (detail::dotInOrder(w.head_weight.row(c), ws.h.col(j), D) + w.head_bias(c)) * w.a_std(j) +
                       w.a_mean(j);
}

/// The network's action for this tick from ws.chunk and the chunks of the last C − 1 ticks (the
/// temporal ensemble: the entry for this tick of every chunk that has one, weighted by age,
/// PolicyWeights::ensemble_weight), rad. Reads, writes nothing. Real-time safe.
template <class Dims>
Eigen::Matrix<float, 5, 1> ensembledAction(const PolicyWeights<Dims>& w, const PolicyWorkspace<Dims>& ws) {
  const int C = w.chunk;
  const int have = static_cast<int>(std::min<std::int64_t>(ws.ticks + 1, C));  // chunks with an entry for now
  const auto& weight = w.ensemble_weight[static_cast<std::size_t>(have - 1)];
  Eigen::Matrix<float, 5, 1> a = weight[0] * ws.chunk.col(0);
  for (int k = 1; k < have; ++k) {
    const auto& old = ws.chunk_ring[static_cast<std::size_t>((ws.ticks - k) % C)];
    a += weight[static_cast<std::size_t>(k)] * old.col(k);
  }
  return a;
}

/// The last part of a step: ws.net_action = ensembledAction, ws.action = that plus the model's
/// law (reference mode: law.gain ⊙ r), ws.chunk into the ring, and the stream advanced.
/// @return ws.action: a_j(t), rad per step, joint order. Real-time safe.
template <class Dims>
const Eigen::Matrix<float, 5, 1>& commitPolicyTick(const PolicyWeights<Dims>& w, PolicyWorkspace<Dims>& ws,
                                                    const PolicyInput& in) {
  ws.net_action = ensembledAction(w, ws);
  ws.action = ws.net_action;
  if (w.conditioning == Conditioning::kReference)
    ws.action += (w.law_gain.array() * in.r.array()).matrix();
  ws.chunk_ring[static_cast<std::size_t>(ws.ticks % w.chunk)] = ws.chunk;
  ++ws.ticks;
  return ws.action;
}

/// One policy step (docs/policy.md): encodePolicyTick, decodePolicyTick, commitPolicyTick.
/// Non-finite inputs give non-finite actions (the caller checks) and poison the window until
/// resetPolicyStream. Writes the attention record and the intermediates into ws.
/// @return ws.action: a_j(t), rad per step, joint order. Real-time safe: no allocation, no
///         exception, no I/O; deterministic (fixed summation order, no FMA contraction).
template <class Dims>
const Eigen::Matrix<float, 5, 1>& stepPolicy(const PolicyWeights<Dims>& w, PolicyWorkspace<Dims>& ws,
                                              const PolicyInput& in) {
  encodePolicyTick(w, ws, in);
  decodePolicyTick(w, ws);
  return commitPolicyTick(w, ws, in);
}

/// Index of the key pose of `movement` nearest to q (Euclidean, rad; ties to the lower index,
/// the rule of toolchain kmeans nearestCentroid). Movement clamped to 0..M-1; a non-finite q
/// gives 0. Real-time safe.
/// @param q joint angles, rad (5; float or double)
template <class Dims, class Derived>
int snapToCentroid(const PolicyWeights<Dims>& w, int movement, const Eigen::MatrixBase<Derived>& q) {
  static_assert(Derived::SizeAtCompileTime == Dims::kTokens, "q must have one entry per joint");
  const int m = std::clamp(movement, 0, w.movements - 1);
  int best = 0;
  double best_d = std::numeric_limits<double>::infinity();
  for (int k = 0; k < w.clusters; ++k) {
    double d = 0.0;
    for (int j = 0; j < Dims::kTokens; ++j) {
      const double diff = static_cast<double>(w.centroids(j, m * w.clusters + k)) - static_cast<double>(q[j]);
      d += diff * diff;
    }
    if (d < best_d) {
      best_d = d;
      best = k;
    }
  }
  return best;
}

/// Key pose k of `movement`, rad (both indices clamped). Real-time safe.
template <class Dims>
Eigen::Matrix<float, 5, 1> centroid(const PolicyWeights<Dims>& w, int movement, int k) {
  const int m = std::clamp(movement, 0, w.movements - 1);
  const int kc = std::clamp(k, 0, w.clusters - 1);
  return w.centroids.col(m * w.clusters + kc);
}

// The step's two halves for the paper and the small configuration are compiled once, in nao_core
// (policy_instances.cpp), not in every program and test that steps them: their fixed-size kernels
// are most of a build's compile time. Other dimensions (a generated model's) instantiate where used.
#define NAO_POLICY_STEP_INSTANCES(EXTERN, D)                                                            \
  EXTERN template void encodePolicyTick<D>(const PolicyWeights<D>&, PolicyWorkspace<D>&, const PolicyInput&); \
  EXTERN template void decodePolicyTick<D>(const PolicyWeights<D>&, PolicyWorkspace<D>&, unsigned);
NAO_POLICY_STEP_INSTANCES(extern, PaperPolicyDims)
NAO_POLICY_STEP_INSTANCES(extern, SmallPolicyDims)

}  // namespace nao
