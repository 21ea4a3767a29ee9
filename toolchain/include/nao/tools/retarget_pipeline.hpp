// From a 3D human skeleton sequence to NAO joint trajectories: human kinematics with the
// demonstration's own scale, paper eq. 2 scaling onto the robot, then Algorithm 1 per frame.
#pragma once

#include "nao/human_kinematics.hpp"
#include "nao/retarget.hpp"
#include "nao/tools/retarget_ceres.hpp"
#include "nao/tools/skeleton_csv.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace nao::tools {

/// Bits of RetargetRow::flags above the RetargetFlags byte.
enum RetargetRowFlags : std::uint32_t {
  kRowHumanMissing = 1u << 8,   ///< the human arm was not measured: previous solution held
  kRowHandNotSeen = 1u << 9,    ///< no hand points: solved without a pointing-direction target
};

struct RetargetOptions {
  /// Algorithm 1's tuning. retargetSkeleton / retargetSkeletonLm bound each sample's step by the
  /// skeleton's own sample interval (skeletonStepTime) in place of a positive params.step_time_s
  /// (<= 0 keeps the steps unbounded).
  RetargetParams params;
  HumanKinematicsConfig human;
  /// Add the hand's pointing direction as a target when the hand is seen. Off by default: x_target
  /// of paper eq. 2 is a position, and NAO (no wrist pitch) cannot in general meet position and
  /// direction together, which makes the weighted problem multimodal (tests/test_retarget.cpp).
  bool use_pointing = false;
  bool use_ceres = true;     ///< the offline Ceres solver (else the runtime's fixed-size LM)
};

/// One output row (docs/formats.md, retarget CSV).
struct RetargetRow {
  double t_s = 0.0;
  RetargetFrame target;   ///< x_target (torso frame, m), q_target (rad), pointing direction
  RetargetResult result;  ///< q_x, q_q, q_r, hands reached, solver flags
  std::uint32_t flags = 0;  ///< RetargetFlags | RetargetRowFlags
};

/// Targets of every frame: human arm kinematics of `frames` with d_h fixed to the
/// demonstration's median link lengths, x_target = robot shoulder + (d_r / d_h) p_h (paper
/// eq. 2), q_target = the five NAO-mapped human angles. Frames where the human arm was not
/// measured get `ok[i] = false`. Throws UserError when no frame has a measurable arm.
std::vector<RetargetFrame> retargetTargets(const ArmModel& arm, const Skeleton& frames,
                                           const RetargetOptions& options, std::vector<bool>& ok,
                                           std::vector<bool>& hand_seen);

/// The time between samples of `frames` (the median of the positive differences of t_s), s;
/// `fallback` when there are fewer than two samples.
double skeletonStepTime(const Skeleton& frames, double fallback);

/// Solves one frame of Algorithm 1 for retargetSkeletonWith: (targets, pointing direction or
/// nullptr) -> the frame's result; warm starts are the solver's own state.
using RetargetFrameSolver =
    std::function<const RetargetResult&(const RetargetFrame& target, const Eigen::Vector3d* u_target_TH)>;

/// Algorithm 1 over the whole sequence, each measured frame solved by `solve`, in order. A frame
/// whose human arm was not measured holds the previous solution (before the first measurement,
/// the first one) and is flagged.
std::vector<RetargetRow> retargetSkeletonWith(const ArmModel& arm, const Skeleton& frames,
                                              const RetargetOptions& options, const RetargetFrameSolver& solve);

/// retargetSkeletonWith the runtime's fixed-size LM (nao::solveRetarget), warm-started frame to
/// frame; options.use_ceres is ignored. Needs no Ceres: nao_rt's reference library
/// (nao_reference) has it.
std::vector<RetargetRow> retargetSkeletonLm(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options);

/// retargetSkeletonWith the solver options.use_ceres names: Ceres (offline reference) or the
/// runtime's LM (retargetSkeletonLm). Defined in retarget_ceres.cpp: links Ceres
/// (nao_toolchain_lib, not nao_reference).
std::vector<RetargetRow> retargetSkeleton(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options);

/// Header and rows of the retarget CSV; `params` holds the setting the rows' q_r was made with
/// (priority, lambda_q, posture weights: written on every row). Throws UserError if the file
/// cannot be written.
void writeRetargetCsv(const std::string& path, const std::vector<RetargetRow>& rows, const RetargetParams& params);

/// Reads a retarget CSV back (t_s, q_x, q_q, x_target, hands reached, flags, q_target, q_r) and,
/// when `setting` is given, writes the retargeting setting of its q_r into it (priority,
/// lambda_q, posture_weights; other fields untouched). Throws UserError naming the file, line and
/// column for a missing column or a bad value, or for rows of mixed settings.
std::vector<RetargetRow> readRetargetCsv(const std::string& path, RetargetParams* setting = nullptr);

/// True when a and b choose q_r the same way (priority, lambda_q, posture weights).
bool sameRetargetSetting(const RetargetParams& a, const RetargetParams& b);

/// {"priority": "hand"|"joints", "lambda_q": x, "posture_weights": [5]}: the retargeting setting
/// as centroids.json and model.bin metadata record it (nao_rt applies it: runtime/app).
nlohmann::json retargetSettingJson(const RetargetParams& params);

}  // namespace nao::tools
