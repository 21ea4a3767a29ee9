// Retargeting of a whole skeleton sequence (nao/retarget_sequence.hpp).
#include "nao/retarget_sequence.hpp"

#include <algorithm>

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
  const RetargetRow* previous = nullptr;
  std::size_t n_leading = 0;  // rows before the first measurement
  for (std::size_t i = 0; i < frames.size(); ++i) {
    RetargetRow& row = rows[i];
    row.t_s = frames[i].t_s;
    if (!ok[i]) {
      // Never invent a target: hold what was solved last (or wait for the first measurement).
      if (previous) {
        row.target = previous->target;
        row.result = previous->result;
      } else {
        ++n_leading;
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
  // Before the first measurement the first solution is held too (backwards), so the trajectory
  // starts at rest there instead of jumping to it from an arbitrary pose.
  for (std::size_t i = 0; i < n_leading && previous != nullptr; ++i) {
    rows[i].target = rows[n_leading].target;
    rows[i].result = rows[n_leading].result;
    rows[i].result.flags = 0;
  }
  return rows;
}

double skeletonStepTime(const Skeleton& frames, double fallback) {
  std::vector<double> dt;
  for (std::size_t i = 1; i < frames.size(); ++i)
    if (frames[i].t_s > frames[i - 1].t_s) dt.push_back(frames[i].t_s - frames[i - 1].t_s);
  if (dt.empty()) return fallback;
  std::nth_element(dt.begin(), dt.begin() + static_cast<long>(dt.size() / 2), dt.end());
  return dt[dt.size() / 2];
}

std::vector<RetargetRow> retargetSkeletonLm(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options) {
  RetargetParams params = options.params;
  if (params.step_time_s > 0.0) params.step_time_s = skeletonStepTime(frames, params.step_time_s);
  RetargetData lm;
  resetRetarget(lm);
  return retargetSkeletonWith(arm, frames, options,
                              [&](const RetargetFrame& t, const Eigen::Vector3d* u) -> const RetargetResult& {
                                return solveRetarget(arm, params, lm, t.p_target_TH, t.q_target, u);
                              });
}

}  // namespace nao
