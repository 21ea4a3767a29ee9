// A recorded human reference (nao_rt --reference file:PATH, docs/nao_rt.md): a 10 Hz skeleton CSV
// prepared at configure time into fixed buffers the 10 Hz loop only reads, with the
// demonstration's calibrated human scale (one d_h from all its frames, as the training data was
// retargeted) and its evaluation target: the feature-extracted trajectory of the same
// demonstration, built with the model's key poses and the runtime's own retargeting.
// Configure-time code: reads files, allocates, throws InputError.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/retarget.hpp"
#include "nao/skeleton_csv.hpp"

#include <string>
#include <vector>

namespace nao {

struct ReferenceStream {
  std::string description;             ///< e.g. "file:out/demo/elbow_000/skeleton.csv"
  std::string movement;                ///< movement name, as in model.bin
  double rate_hz = 10.0;
  std::vector<SkeletonFrame> frames;   ///< one per tick, world frame
  std::vector<bool> present;           ///< false: no human in this tick (nullptr to the controller)
  HumanKinematicsConfig human;         ///< with the demonstration's human scale d_h fixed
  std::vector<JointVector> retargeted; ///< offline Algorithm 1 (q_r) per tick, held where no human
  std::vector<bool> measured;          ///< a human arm was measured in this tick
  std::vector<JointVector> target;     ///< feature-extracted trajectory per tick (evaluation)
};

/// Reads a skeleton CSV (docs/formats.md) sampled at 10 Hz and prepares it for `movement`.
/// Throws InputError naming the file and the problem.
ReferenceStream makeFileReference(const ArmModel& arm, const std::string& path, const std::string& movement,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget = {});

/// Fills human, retargeted, measured and target of a stream whose frames and present flags are
/// set (used by both makers; exposed for tests).
void prepareReference(const ArmModel& arm, ReferenceStream& stream, const std::vector<JointVector>& centroids,
                      const RetargetParams& retarget = {});

}  // namespace nao
