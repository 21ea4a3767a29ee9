// Synthetic references for the toolchain and the tests: a synthesised demonstration rendered
// into two cameras with the synthesiser's noise and dropouts, triangulated and resampled to
// 10 Hz — the 3D keypoints a live two-camera OpenPose rig would stream — and prepared like nao_rt
// prepares a recorded reference (nao/reference_stream.hpp), with its evaluation target.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"

#include "nao/reference_stream.hpp"
#include "nao/retarget.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

/// Run seeds of held-out synthetic references: kReferenceSeedBase + N is far from the training
/// set's seeds (the paper set uses seed 1), so such a reference is never a training
/// demonstration (toolchain/nao demo synthesises seed 1000001).
inline constexpr std::uint64_t kReferenceSeedBase = 1000000;

/// Synthesises demonstration `index` of `movement` with run seed kReferenceSeedBase + seed, and
/// prepares it. `centroids` are the movement's key poses (from model.bin); `retarget` the model's
/// retargeting setting (priority, lambda_q, posture weights). Throws UserError.
ReferenceStream makeSyntheticReference(const ArmModel& arm, Movement movement, std::uint64_t seed, int index,
                                       const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// Demonstration `index` of `movement` exactly as `nao_toolchain synth --seed run_seed` makes
/// it (no kReferenceSeedBase offset: with the training run seed this IS a training or
/// validation demonstration), streamed and prepared like makeSyntheticReference. The evaluation
/// regenerates a model's held-out demonstrations with it. Throws UserError.
ReferenceStream makeDemoReference(const ArmModel& arm, Movement movement, std::uint64_t run_seed, int index,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// What the toolchain sees of a synthetic demonstration: its cameras rendered as OpenPose
/// detections, triangulated, and resampled to `rate_hz` (Hz). Throws UserError.
Skeleton observeDemo(const SynthDemo& demo, double rate_hz = 10.0);

// The recorded reference and its preparation are the runtime's (nao/reference_stream.hpp).
using nao::makeFileReference;
using nao::prepareReference;
using nao::ReferenceStream;

}  // namespace nao::tools
