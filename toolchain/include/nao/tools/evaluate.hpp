// `nao_toolchain evaluate` (issue 13, docs/evaluate.md): the paper's autonomous protocol and the
// reference-mode bar, scored the way nao_rt scores a run. The helpers here are the pieces the
// tests check on their own: hand paths, nearest-demonstration DTW (rt::dtwMeanDistance, the
// runtime's), medians, and the held-out demonstrations regenerated (heldout.hpp names them).
// Offline code (nao_eval_lib, links nao_rt_metrics): allocates, may throw.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/reference_source.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

using HandPath = std::vector<Eigen::Vector3d>;

/// Hand points (torso frame, m) of a joint trajectory by forward kinematics.
HandPath handPath(const ArmModel& arm, const std::vector<JointVector>& q);

/// Median of `v` (mean of the two middle values for an even count); NaN when empty.
double median(std::vector<double> v);

/// The demonstration of `demos` nearest to `path` by rt::dtwMeanDistance(path, demo), skipping
/// index `exclude` (-1: none). Ties go to the lower index.
struct NearestDemo {
  double dtw_m = 0.0;
  int index = -1;
};
NearestDemo nearestDemo(const HandPath& path, const std::vector<HandPath>& demos, int exclude = -1);

/// The held-out demonstrations of one movement: the autonomous model's split.val entries of the
/// movement, regenerated (synthesiser, cameras, triangulation, the runtime's retargeting with the
/// model's setting, the model's key poses).
struct HeldOutDemos {
  std::string movement;
  std::uint64_t seed = 1;
  bool seed_assumed = true;
  std::vector<std::string> names;
  std::vector<int> indices;
  std::vector<std::vector<JointVector>> target;  ///< feature-extracted trajectory per demo, rad
  std::vector<HandPath> hand;                    ///< its hand path
};

/// Regenerates demonstrations `indices` of `movement` (synth run seed `seed`): their
/// feature-extracted trajectories.
std::vector<std::vector<JointVector>> regenerateTargets(const ArmModel& arm, const std::string& movement,
                                                        std::uint64_t seed, const std::vector<int>& indices,
                                                        const std::vector<JointVector>& key_poses,
                                                        const RetargetParams& retarget);

}  // namespace nao::tools
