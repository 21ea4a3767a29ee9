// From a recorded 3D human skeleton sequence to NAO joint trajectories: human kinematics with the
// demonstration's own scale, paper eq. 2 scaling onto the robot, then Algorithm 1 per frame
// (docs/retargeting.md). nao_rt prepares a recorded reference with it (the runtime's fixed-size LM); the
// toolchain's retargeting runs the same sequence with Ceres (tools/retarget_pipeline.hpp).
// Configure-time code: allocates, throws InputError.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/retarget.hpp"
#include "nao/body25.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <vector>

namespace nao {

/// One frame's targets.
struct RetargetFrame {
  Eigen::Vector3d p_target_TH = Eigen::Vector3d::Zero();  ///< x_target, torso frame, m
  JointVector q_target = JointVector::Zero();             ///< human joint angles in NAO's order, rad
  bool has_pointing = false;                              ///< whether u_target_TH is used
  Eigen::Vector3d u_target_TH = Eigen::Vector3d::UnitX(); ///< hand pointing direction, torso frame
};

/// Bits of RetargetRow::flags above the RetargetFlags byte.
enum RetargetRowFlags : std::uint32_t {
  kRowHumanMissing = 1u << 8,   ///< the human arm was not measured: previous solution held
  kRowHandNotSeen = 1u << 9,    ///< no hand points: solved without a pointing-direction target
};

struct RetargetOptions {
  /// Algorithm 1's tuning. The sequence solvers bound each sample's step by the skeleton's own
  /// sample interval (skeletonStepTime) in place of a positive params.step_time_s (<= 0 keeps the
  /// steps unbounded).
  RetargetParams params;
  HumanKinematicsConfig human;
  /// Add the hand's pointing direction as a target when the hand is seen. Off by default: x_target
  /// of paper eq. 2 is a position, and NAO (no wrist pitch) cannot in general meet position and
  /// direction together, which makes the weighted problem multimodal (tests/test_retarget.cpp).
  bool use_pointing = false;
  /// The toolchain's retargetSkeleton: the offline Ceres solver (else the runtime's fixed-size
  /// LM). retargetSkeletonLm ignores it.
  bool use_ceres = true;
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
/// measured get `ok[i] = false`. Throws InputError when no frame has a measurable arm.
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
/// whose human arm was not measured holds the previous solution and is flagged.
std::vector<RetargetRow> retargetSkeletonWith(const ArmModel& arm, const Skeleton& frames,
                                              const RetargetOptions& options, const RetargetFrameSolver& solve);

/// retargetSkeletonWith the runtime's fixed-size LM (nao::solveRetarget), warm-started frame to
/// frame; options.use_ceres is ignored. What nao_rt prepares a recorded reference with.
std::vector<RetargetRow> retargetSkeletonLm(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options);

}  // namespace nao
