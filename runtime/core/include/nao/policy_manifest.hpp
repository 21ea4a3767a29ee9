// The policy's tensor table, written once: every manifest tensor - name, shape, role - in
// canonical order, with where its view lives in PolicyWeights. policyManifest (the model.bin
// writer and reader, codegen, the trainer) and the runtime's views (binding by name or at the
// generated offsets, the int8 and packed copies, warming, the view count) all walk this one
// table, so the runtime's view order cannot drift from the manifest's.
//
// The walk allocates nothing and names each tensor in parts (ViewName), so the runtime may walk
// it in the loop (warmPolicy); policyManifest turns it into TensorSpecs at configure time.
#pragma once

#include "nao/policy_config.hpp"

#include <array>
#include <cstddef>
#include <string>

namespace nao {

/// A manifest shape, row-major (matrices [in, out]), rank 1 to 3; no allocation.
struct ManifestShape {
  int rank = 0;
  std::array<int, 3> dim{};
};

/// The sizes the table reads: PolicyArch's fields of the same names (policyManifest) or a
/// compiled Dims' with the bound model's table sizes (the views, policyViewCount).
struct PolicySizes {
  int d_model = 0, heads = 0, encoder_layers = 0, decoder_layers = 0, tokens = 0, features = 0;
  int movements = 0, clusters = 0, max_steps = 0, window = 0, chunk = 1;
  std::array<int, 3> ffn_hidden{};
};

namespace detail {

/// The manifest name of one tensor, kept in parts so that walking the table costs no string:
/// head[.layer][.mid][.sub][.tail], e.g. {"enc", 0, "attn", "wq"} is "enc.0.attn.wq" and
/// {"dec", 1, "ffn", "bias", 2} is "dec.1.ffn.2.bias".
struct ViewName {
  const char* head;
  int layer = -1;           ///< -1: none
  const char* mid = nullptr;
  const char* tail = nullptr;
  int sub = -1;             ///< -1: none
  std::string str() const {
    std::string s = head;
    if (layer >= 0) s += "." + std::to_string(layer);
    if (mid != nullptr) (s += ".") += mid;
    if (sub >= 0) s += "." + std::to_string(sub);
    if (tail != nullptr) (s += ".") += tail;
    return s;
  }
};

constexpr ManifestShape shape1(int a) { return {1, {a, 0, 0}}; }
constexpr ManifestShape shape2(int a, int b) { return {2, {a, b, 0}}; }
constexpr ManifestShape shape3(int a, int b, int c) { return {3, {a, b, c}}; }

// FFN layer k's weight (with its int8 / packed companion) and bias: the runtime holds exactly
// three hidden layers (checkPolicyArch), other depths exist only as manifests.
template <class Ffn, class G>
void ffnWeight(Ffn& n, std::size_t k, G&& g) {
  if (k == 0) g(n.w0, n.w0q);
  if (k == 1) g(n.w1, n.w1q);
  if (k == 2) g(n.w2, n.w2q);
  if (k == 3) g(n.w3, n.w3q);
}
template <class Ffn, class G>
void ffnBias(Ffn& n, std::size_t k, G&& g) {
  if (k == 0) g(n.b0);
  if (k == 1) g(n.b1);
  if (k == 2) g(n.b2);
  if (k == 3) g(n.b3);
}

template <class S, class Acc>
constexpr void tableNorm(S& s, const char* head, int layer, const char* mid, int d, Acc at) {
  s(ViewName{head, layer, mid, "gain"}, shape1(d), TensorRole::kTrained,
    [at](auto& w, auto&& g) { at(w, [&](auto& n) { g(n.gain); }); });
  s(ViewName{head, layer, mid, "bias"}, shape1(d), TensorRole::kTrained,
    [at](auto& w, auto&& g) { at(w, [&](auto& n) { g(n.bias); }); });
}

template <class S, class Acc>
constexpr void tableAttention(S& s, const char* head, int layer, const char* mid, int d, Acc at) {
  constexpr TensorRole M = TensorRole::kMatrix, T = TensorRole::kTrained;
  s(ViewName{head, layer, mid, "wq"}, shape2(d, d), M, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.wq, a.wq8); }); });
  s(ViewName{head, layer, mid, "bq"}, shape1(d), T, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.bq); }); });
  s(ViewName{head, layer, mid, "wk"}, shape2(d, d), M, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.wk, a.wk8); }); });
  s(ViewName{head, layer, mid, "bk"}, shape1(d), T, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.bk); }); });
  s(ViewName{head, layer, mid, "wv"}, shape2(d, d), M, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.wv, a.wv8); }); });
  s(ViewName{head, layer, mid, "bv"}, shape1(d), T, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.bv); }); });
  s(ViewName{head, layer, mid, "wo"}, shape2(d, d), M, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.wo, a.wo8); }); });
  s(ViewName{head, layer, mid, "bo"}, shape1(d), T, [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.bo); }); });
}

// Attention over the window: plus age_bias [H, W] (b_h(age), added to head h's score of a key
// `age` ticks older than its query; it depends on the age alone, so cached keys stay valid).
template <class S, class Acc>
constexpr void tableTemporalAttention(S& s, const char* head, int layer, const char* mid, int d, int heads,
                                      int window, Acc at) {
  tableAttention(s, head, layer, mid, d, at);
  s(ViewName{head, layer, mid, "age_bias"}, shape2(heads, window), TensorRole::kTrained,
    [at](auto& w, auto&& g) { at(w, [&](auto& a) { g(a.age_bias); }); });
}

template <class Sizes, class S, class Acc>
constexpr void tableFfn(S& s, const char* head, int layer, const Sizes& a, Acc at) {
  int in = a.d_model;
  for (std::size_t k = 0; k <= a.ffn_hidden.size(); ++k) {
    const int out = k < a.ffn_hidden.size() ? a.ffn_hidden[k] : a.d_model;
    s(ViewName{head, layer, "ffn", "weight", static_cast<int>(k)}, shape2(in, out), TensorRole::kMatrix,
      [at, k](auto& w, auto&& g) { at(w, [&](auto& n) { ffnWeight(n, k, g); }); });
    s(ViewName{head, layer, "ffn", "bias", static_cast<int>(k)}, shape1(out), TensorRole::kTrained,
      [at, k](auto& w, auto&& g) { at(w, [&](auto& n) { ffnBias(n, k, g); }); });
    in = out;
  }
}

}  // namespace detail

/// The table. Calls s(ViewName, ManifestShape, TensorRole, at) for every tensor of an
/// architecture of sizes `a` (PolicyArch or PolicySizes), in manifest order; `at(w, g)` calls
/// g(view) on the tensor's view in a PolicyWeights `w`, or g(view, quant) with its int8 / packed
/// companion for a TensorRole::kMatrix tensor (a sink that never calls `at` needs no
/// PolicyWeights). No allocation.
template <class Sizes, class S>
constexpr void walkPolicyManifest(const Sizes& a, S&& s) {
  using detail::ViewName;
  using detail::shape1;
  using detail::shape2;
  constexpr TensorRole T = TensorRole::kTrained, F = TensorRole::kFixed;
  const int d = a.d_model, J = a.tokens;
  s(ViewName{"embed.in.weight"}, shape2(a.features, d), T, [](auto& w, auto&& g) { g(w.embed_in_weight); });
  s(ViewName{"embed.in.bias"}, shape1(d), T, [](auto& w, auto&& g) { g(w.embed_in_bias); });
  s(ViewName{"embed.joint_enc"}, shape2(J, d), T, [](auto& w, auto&& g) { g(w.embed_joint_enc); });
  s(ViewName{"embed.movement"}, shape2(a.movements, d), T, [](auto& w, auto&& g) { g(w.embed_movement); });
  s(ViewName{"embed.step"}, shape2(a.max_steps, d), T, [](auto& w, auto&& g) { g(w.embed_step); });
  s(ViewName{"embed.act.weight"}, shape2(1, d), T, [](auto& w, auto&& g) { g(w.embed_act_weight); });
  s(ViewName{"embed.act.bias"}, shape1(d), T, [](auto& w, auto&& g) { g(w.embed_act_bias); });
  s(ViewName{"embed.joint_dec"}, shape2(J, d), T, [](auto& w, auto&& g) { g(w.embed_joint_dec); });
  for (int l = 0; l < a.encoder_layers; ++l) {
    const auto layer = [l](auto& w, auto&& g) { g(w.enc[static_cast<std::size_t>(l)]); };
    const auto ln1 = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ln1); }); };
    const auto attn = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.attn); }); };
    const auto ln2 = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ln2); }); };
    const auto ffn = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ffn); }); };
    detail::tableNorm(s, "enc", l, "ln1", d, ln1);
    detail::tableTemporalAttention(s, "enc", l, "attn", d, a.heads, a.window, attn);
    detail::tableNorm(s, "enc", l, "ln2", d, ln2);
    detail::tableFfn(s, "enc", l, a, ffn);
  }
  detail::tableNorm(s, "enc.norm", -1, nullptr, d, [](auto& w, auto&& g) { g(w.enc_norm); });
  for (int l = 0; l < a.decoder_layers; ++l) {
    const auto layer = [l](auto& w, auto&& g) { g(w.dec[static_cast<std::size_t>(l)]); };
    const auto ln1 = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ln1); }); };
    const auto self = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.self); }); };
    const auto ln2 = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ln2); }); };
    const auto cross = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.cross); }); };
    const auto ln3 = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ln3); }); };
    const auto ffn = [layer](auto& w, auto&& g) { layer(w, [&](auto& e) { g(e.ffn); }); };
    detail::tableNorm(s, "dec", l, "ln1", d, ln1);
    detail::tableAttention(s, "dec", l, "self", d, self);
    detail::tableNorm(s, "dec", l, "ln2", d, ln2);
    detail::tableTemporalAttention(s, "dec", l, "cross", d, a.heads, a.window, cross);
    detail::tableNorm(s, "dec", l, "ln3", d, ln3);
    detail::tableFfn(s, "dec", l, a, ffn);
  }
  detail::tableNorm(s, "dec.norm", -1, nullptr, d, [](auto& w, auto&& g) { g(w.dec_norm); });
  const int C = a.chunk;
  // Token j's row of the chunk: a_j(t) .. a_j(t+C-1), normalised.
  s(ViewName{"head.weight"}, shape2(d, C), T, [](auto& w, auto&& g) { g(w.head_weight); });
  s(ViewName{"head.bias"}, shape1(C), T, [](auto& w, auto&& g) { g(w.head_bias); });
  // w_k = exp(-decay k): the weight of the chunk made k ticks ago in the executed action.
  if (C > 1) s(ViewName{"head.ensemble_decay"}, shape1(1), F, [](auto& w, auto&& g) { g(w.head_ensemble_decay); });
  // Laws the runtime adds to the network's action: gain_j r_j (reference mode; 0 autonomous).
  s(ViewName{"law.gain"}, shape1(J), F, [](auto& w, auto&& g) { g(w.law_gain); });
  s(ViewName{"norm.q_mean"}, shape1(J), F, [](auto& w, auto&& g) { g(w.q_mean); });
  s(ViewName{"norm.q_std"}, shape1(J), F, [](auto& w, auto&& g) { g(w.q_std); });
  s(ViewName{"norm.a_mean"}, shape1(J), F, [](auto& w, auto&& g) { g(w.a_mean); });
  s(ViewName{"norm.a_std"}, shape1(J), F, [](auto& w, auto&& g) { g(w.a_std); });
  s(ViewName{"norm.r_mean"}, shape1(J), F, [](auto& w, auto&& g) { g(w.r_mean); });
  s(ViewName{"norm.r_std"}, shape1(J), F, [](auto& w, auto&& g) { g(w.r_std); });
  s(ViewName{"centroids"}, detail::shape3(a.movements, a.clusters, J), F, [](auto& w, auto&& g) { g(w.centroids); });
}

}  // namespace nao
