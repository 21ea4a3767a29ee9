// The policy's architecture and its manifest: the one table of tensor names and shapes that
// the model.bin writer and reader, the code generator, the runtime's views and the shape
// tests all walk (docs/policy.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nao {

/// What the encoder is conditioned on. Data in model.bin, not a compiled architecture.
enum class Conditioning : std::uint32_t {
  kReference = 0,   ///< r_j(t): the snapped human key pose
  kAutonomous = 1,  ///< paper §4.1: movement + step embeddings, no reference
};

const char* conditioningName(Conditioning c);

/// Input features per token: q_j(t), a_j(t-1), r_j(t).
inline constexpr int kPolicyFeatures = 3;

/// Dimensions of the encoder-decoder (everything a compiled runtime must agree on).
struct PolicyArch {
  int d_model = 128;
  int heads = 4;
  int encoder_layers = 4;
  int decoder_layers = 4;
  std::vector<int> ffn_hidden{512, 512, 512};  ///< widths of the FFN's hidden layers
  int tokens = 5;                              ///< body parts = robot joints
  int features = kPolicyFeatures;
  int movements = 3;
  int clusters = 10;                           ///< key poses per movement (k-means K)
  int max_steps = 256;                         ///< step-embedding rows (autonomous mode)
  /// W: ticks of history the encoder and the cross-attention see (the current tick included),
  /// 20 ticks = 2 s at 10 Hz. The runtime keeps a key/value ring of W ticks.
  int window = 20;
  /// C: actions each action token predicts per tick, a(t) .. a(t+C-1) of its joint (an action
  /// chunk); the executed action averages the chunks of the last C ticks (temporal ensembling).
  /// 1: the next action only.
  int chunk = 1;

  bool operator==(const PolicyArch& o) const;
  bool operator!=(const PolicyArch& o) const { return !(*this == o); }
};

/// Paper configuration (paper §4.1): 4+4 layers, 4 heads, d_model 128, FFN 128-512-512-512-128,
/// one action per tick, regression head.
PolicyArch paperArch();
/// Small configuration for tests: 2+2 layers, 4 heads, d_model 32, FFN 32-64-64-64-32, window 8.
PolicyArch smallArch();

/// Empty if the architecture is usable, else what is wrong (e.g. "d_model 130 is not a
/// multiple of heads 4").
std::string archProblem(const PolicyArch& arch);

/// What a manifest tensor is to the code that reads it.
enum class TensorRole : std::uint8_t {
  /// Trained: a weight matrix every layer multiplies by (the attention projections wq, wk, wv,
  /// wo and the FFN weights). Also held as int8 and packed fp32 copies, in manifest order
  /// (nao/quantize.hpp; PolicyWeights' QuantView beside its view).
  kMatrix,
  /// Trained: any other tensor (embeddings, biases, layer norms, age biases, the head).
  kTrained,
  /// Set from the data set, not trained (torch buffers): the normalisation, the key poses, the
  /// law, the temporal ensemble's decay.
  kFixed,
};

struct TensorSpec {
  std::string name;
  std::vector<int> shape;  ///< row-major; matrices [in, out]
  TensorRole role = TensorRole::kTrained;
  std::size_t count() const;
};

/// The model contract, the one manifest: every tensor of a policy with this architecture -
/// name, shape, role - in canonical order (docs/policy.md). model.bin's writer and reader, the
/// generated code (offsets and extents), the runtime's views (bound by name and checked against
/// the roles), the int8 and packed blobs (the kMatrix entries, in this order) and the trainer's
/// torch module (its parameters and buffers by name, shape and role) all follow it.
std::vector<TensorSpec> policyManifest(const PolicyArch& arch);

/// The extent [rows, cols] of a tensor's Eigen view (column-major): the row-major [a_0, ..., a_n]
/// is [a_n, a_0 ... a_{n-1}], a vector [a_0] is [a_0, 1].
struct TensorExtent {
  std::int64_t rows = 1;
  std::int64_t cols = 1;
  bool operator==(const TensorExtent& o) const { return rows == o.rows && cols == o.cols; }
};
TensorExtent viewExtent(const TensorSpec& spec);

/// Total float count of the manifest.
std::size_t parameterCount(const PolicyArch& arch);

}  // namespace nao
