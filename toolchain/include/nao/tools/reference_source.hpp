// Reference sources of nao_rt (issue 5): the human demonstration a run imitates, prepared at
// configure time into fixed buffers the 10 Hz loop only reads.
//   synthetic:<movement>  a fresh synthesised demonstration (seeds never used for training),
//                         rendered into two cameras with the synthesiser's noise and dropouts,
//                         triangulated and resampled to 10 Hz — the 3D keypoints a live
//                         two-camera OpenPose rig would stream;
//   file:<path>           a triangulated BODY25 skeleton CSV from `nao_toolchain triangulate`.
// Each also carries its evaluation target: the feature-extracted trajectory (DESIGN §6) of the
// same demonstration, built offline with the model's key poses.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"

#include "nao/retarget.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

/// Run seed of the synthetic reference for nao_rt --seed N: far from the training set's
/// seeds (the paper set uses seed 1), so a reference is never a training demonstration.
inline constexpr std::uint64_t kReferenceSeedBase = 1000000;

struct ReferenceStream {
  std::string description;             ///< e.g. "synthetic:elbow (seed 1000001, index 0)"
  std::string movement;                ///< movement name, as in model.bin
  double rate_hz = 10.0;
  std::vector<SkeletonFrame> frames;   ///< one per tick, world frame
  std::vector<bool> present;           ///< false: no human in this tick (nullptr to the controller)
  HumanKinematicsConfig human;         ///< with the demonstration's human scale d_h fixed
  std::vector<JointVector> retargeted; ///< offline Algorithm 1 (q_r) per tick, held where no human
  std::vector<bool> measured;          ///< a human arm was measured in this tick
  std::vector<JointVector> target;     ///< feature-extracted trajectory per tick (evaluation)
};

/// Synthesises demonstration `index` of `movement` with run seed kReferenceSeedBase + seed, and
/// prepares it. `centroids` are the movement's key poses (from model.bin); `retarget` the model's
/// retargeting setting (priority, lambda_q, posture weights). Throws UserError.
ReferenceStream makeSyntheticReference(const ArmModel& arm, Movement movement, std::uint64_t seed, int index,
                                       const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// Demonstration `index` of `movement` exactly as `nao_toolchain synth --seed run_seed` makes
/// it (no kReferenceSeedBase offset: with the training run seed this IS a training or
/// validation demonstration), streamed and prepared like makeSyntheticReference. nao_rt uses
/// it to regenerate a model's validation demonstrations (--reference none). Throws UserError.
ReferenceStream makeDemoReference(const ArmModel& arm, Movement movement, std::uint64_t run_seed, int index,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// What the toolchain sees of a synthetic demonstration: its cameras rendered as OpenPose
/// detections, triangulated, and resampled to `rate_hz` (Hz). Throws UserError.
Skeleton observeDemo(const SynthDemo& demo, double rate_hz = 10.0);

/// Reads a skeleton CSV (docs/formats.md) sampled at 10 Hz and prepares it for `movement`.
/// Throws UserError naming the file and the problem.
ReferenceStream makeFileReference(const ArmModel& arm, const std::string& path, const std::string& movement,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// Fills human, retargeted, measured and target of a stream whose frames and present flags are
/// set (used by both makers; exposed for tests).
void prepareReference(const ArmModel& arm, ReferenceStream& stream, const std::vector<JointVector>& centroids,
                      const RetargetParams& retarget = {});

}  // namespace nao::tools
