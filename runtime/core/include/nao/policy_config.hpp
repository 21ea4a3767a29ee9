// The policy's architecture and its manifest: the one table of tensor names and shapes that
// the model.bin writer and reader, the code generator, the runtime's views and the shape
// tests all walk (docs/policy.md, DESIGN §7-8).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nao {

/// What the encoder is conditioned on. Data in model.bin, not a compiled architecture.
enum class Conditioning : std::uint32_t {
  kReference = 0,   ///< r_j(t): the snapped human key pose (DESIGN §7)
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
  /// 20 ticks = 2 s at 10 Hz (DESIGN §7). The runtime keeps a key/value ring of W ticks.
  int window = 20;
  /// C: actions each action token predicts per tick, a(t) .. a(t+C-1) of its joint (an action
  /// chunk); the executed action averages the chunks of the last C ticks (temporal ensembling).
  /// 1: the next action only.
  int chunk = 1;
  /// B: 0, the head regresses the chunk; >= 1, it picks one of B action bins (key chunks of the
  /// training labels, k-means) by its logits and adds that bin's offset (docs/policy.md "Head").
  int bins = 0;

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

struct TensorSpec {
  std::string name;
  std::vector<int> shape;  ///< row-major; matrices [in, out]
  std::size_t count() const;
};

/// Every tensor of a policy with this architecture, in canonical order (docs/policy.md).
std::vector<TensorSpec> policyManifest(const PolicyArch& arch);

/// Total float count of the manifest.
std::size_t parameterCount(const PolicyArch& arch);

}  // namespace nao
