// What a model.bin carries for a run beyond its tensors (a run needs
// nothing else), as types: the movement names, the autonomous starts, the demonstrated workspace,
// the run codes, the retargeting setting, and the training split and data fingerprint the
// evaluation checks against. nao_io decodes the file's metadata into a ModelSpec once, at
// configure time (readModelSpec, nao/model_file.hpp); the controller only reads it.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/retarget.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nao {

/// One autonomous start: a held-out demonstration's start state.
struct ModelStart {
  std::string name;                     ///< the demonstration, e.g. "elbow_003"
  std::int64_t ticks = 0;               ///< its length, 10 Hz ticks (>= 1)
  JointVector q = JointVector::Zero();  ///< its start pose, rad (the arm starts there at rest, a(−1) = 0)
};

/// Starts per movement, outer index = movement index (ModelHeader::movement_names order).
using ModelStarts = std::vector<std::vector<ModelStart>>;

/// Largest `ticks` a start may give (one hour at 10 Hz: a run's own cap).
inline constexpr std::int64_t kMaxStartTicks = 36000;

/// The joint range a movement's demonstrations cover (their feature trajectories' min and max,
/// rad): where an autonomous run of it may go (the controller's workspace envelope).
struct ModelWorkspace {
  JointVector lo = JointVector::Zero();
  JointVector hi = JointVector::Zero();
};

/// One movement's run codes; n demonstrations, codes of d floats.
struct ModelRunCodes {
  std::vector<std::string> names;  ///< the training demonstrations
  std::vector<JointVector> q;      ///< their start poses, rad
  std::vector<float> code;         ///< n × d, row i the code of demonstration i
  std::vector<double> dtw_m;       ///< n × n, symmetric, zero diagonal: hand-path DTW, m
  int d = 0;
  std::size_t size() const { return names.size(); }
};

/// Starts a run-code choice looks at (as the medoid replay: the 5 nearest).
inline constexpr int kRunCodeNearest = 5;

/// The demonstration whose code a run from `q0` takes: of the kRunCodeNearest starts nearest q0
/// (Euclidean, rad; ties to the lower index), the one with the smallest summed DTW to the others
/// (ties to the nearer). `exclude` (>= 0) leaves that demonstration out, as if the run started
/// where no training demonstration did (the trainer's closed-loop runs from training starts).
/// -1 when no demonstration is left. Real-time safe (no allocation).
int runCodeIndex(const ModelRunCodes& codes, const JointVector& q0, int exclude = -1);

/// The code (codes[movement].d floats) a run of `movement` from `q0` takes, and its index into
/// codes[movement] in `*index` (if not null); nullptr and -1 when the movement has none.
/// Real-time safe.
const float* runCode(const std::vector<ModelRunCodes>& codes, int movement, const JointVector& q0, int* index = nullptr);

/// The demonstrations a model was trained on and held out from training, by name (e.g.
/// "elbow_003"), as its metadata records them; empty lists: none recorded.
struct ModelSplit {
  std::vector<std::string> train;
  std::vector<std::string> val;
};

/// Everything model.bin's header and metadata tell a run, one entry per movement where per
/// movement.
struct ModelSpec {
  std::vector<std::string> movement_names;  ///< index order (ModelHeader::movement_names)
  ModelStarts starts;                     ///< the autonomous starts (empty lists: none recorded)
  std::vector<ModelWorkspace> workspace;  ///< the demonstrated joint ranges (empty: none recorded)
  std::vector<ModelRunCodes> run_codes;   ///< the run codes (empty: a model without a run latent)
  RetargetParams retarget;                ///< the retargeting setting the training data were made with
  ModelSplit split;                       ///< the training / held-out demonstrations
  std::string data_fingerprint;           ///< the training data set's fingerprint (empty: none recorded)
};

}  // namespace nao
