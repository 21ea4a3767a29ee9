// Retargeting of a whole skeleton sequence (nao/retarget_sequence.hpp).
#include "nao/retarget_sequence.hpp"

#include "nao/human_scale.hpp"
#include "nao/input_error.hpp"
#include "nao/kinematics.hpp"

namespace nao {

std::vector<RetargetFrame> retargetTargets(const ArmModel& arm, const Skeleton& frames,
                                           const RetargetOptions& options, std::vector<bool>& ok,
                                           std::vector<bool>& hand_seen) {
  // One scale per demonstration: per-frame link lengths jitter with the keypoint noise, and
  // that jitter would otherwise move the robot's target.
  const HumanArmLengths lengths = estimateHumanArmLengths(frames, options.human);
  if (lengths.n_arm_frames == 0)
    throw InputError("no frame has a measurable right arm (RShoulder, RElbow, RWrist and the torso points)");
  const HumanKinematicsConfig config = withDemoScale(options.human, lengths);
  const double d_r = robotScale(arm);
  const Eigen::Vector3d p_T_shoulder = arm.p_PJ[0];

  std::vector<RetargetFrame> targets(frames.size());
  ok.assign(frames.size(), false);
  hand_seen.assign(frames.size(), false);
  HumanArmData human;
  resetHumanArm(human);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    humanArmKinematics(config, human, frames[i]);
    if (!human.valid) continue;
    ok[i] = true;
    RetargetFrame& t = targets[i];
    t.p_target_TH = p_T_shoulder + scaleHumanEndpoint(d_r, human.d_h_m, human.p_SH_T);
    t.q_target = human.q.head<kNumJoints>();
    // The human hand's x axis (wrist -> middle knuckle) is NAO's hand x axis.
    hand_seen[i] = human.hand_seen;
    t.has_pointing = options.use_pointing && human.hand_seen;
    t.u_target_TH = human.R_TK.col(0);
  }
  return targets;
}

std::vector<RetargetRow> retargetSkeletonWith(const ArmModel& arm, const Skeleton& frames,
                                              const RetargetOptions& options, const RetargetFrameSolver& solve) {
  std::vector<bool> ok, hand_seen;
  const std::vector<RetargetFrame> targets = retargetTargets(arm, frames, options, ok, hand_seen);

  std::vector<RetargetRow> rows(frames.size());
  ArmData kin;
  const RetargetRow* previous = nullptr;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    RetargetRow& row = rows[i];
    row.t_s = frames[i].t_s;
    if (!ok[i]) {
      // Never invent a target: hold what was solved last (or wait for the first measurement).
      if (previous) {
        row.target = previous->target;
        row.result = previous->result;
      } else {
        // Before the first measurement: the zero pose clamped, so every row stays inside the limits.
        row.result.q_x = row.result.q_q = row.result.q_r = clampToLimits(arm, JointVector::Zero());
        row.result.p_TH_x = row.result.p_TH_q = forwardKinematics(arm, kin, row.result.q_x);
      }
      row.result.flags = 0;
      row.flags = kRowHumanMissing;
      continue;
    }
    row.target = targets[i];
    const Eigen::Vector3d* u = row.target.has_pointing ? &row.target.u_target_TH : nullptr;
    row.result = solve(row.target, u);
    row.flags = row.result.flags | (hand_seen[i] ? 0u : kRowHandNotSeen);
    previous = &row;
  }
  return rows;
}

std::vector<RetargetRow> retargetSkeletonLm(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options) {
  RetargetData lm;
  resetRetarget(lm);
  return retargetSkeletonWith(arm, frames, options,
                              [&](const RetargetFrame& t, const Eigen::Vector3d* u) -> const RetargetResult& {
                                return solveRetarget(arm, options.params, lm, t.p_target_TH, t.q_target, u);
                              });
}

}  // namespace nao
