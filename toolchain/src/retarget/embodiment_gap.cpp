#include "nao/tools/embodiment_gap.hpp"
#include "nao/tools/stats.hpp"

#include "nao/kinematics.hpp"
#include "nao/tools/command.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>

namespace nao::tools {
namespace {

// The endpoint H (centre of hand keypoints 0, 5, 9, 17) in the torso frame, shoulder at the origin.
Eigen::Vector3d humanEndpoint(const Anthropometrics& body, const HumanJointVector& q) {
  const HumanArmPoints p =
      humanArmForward(body, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), q);
  Eigen::Vector3d h = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& k : p.p_WHand) h += k;
  return h / static_cast<double>(p.p_WHand.size());
}

}  // namespace

HandPathShares handPathShares(const SynthDemo& demo) {
  std::vector<const HumanJointVector*> circle;
  for (std::size_t i = 0; i < demo.q.size() && i < demo.phase.size(); ++i)
    if (demo.phase[i] == 1) circle.push_back(&demo.q[i]);
  if (circle.size() < 2) throw UserError(demo.name + ": no circle phase");
  HumanJointVector mean = HumanJointVector::Zero();
  for (const HumanJointVector* q : circle) mean += *q;
  mean /= static_cast<double>(circle.size());

  // dH/dq_k at the mean posture, central differences (the chain is smooth; h ~ cbrt(eps)).
  Eigen::Matrix<double, 3, kNumHumanJoints> J;
  constexpr double kStep = 1e-5;
  for (int k = 0; k < kNumHumanJoints; ++k) {
    HumanJointVector a = mean, b = mean;
    a[k] += kStep;
    b[k] -= kStep;
    J.col(k) = (humanEndpoint(demo.body, a) - humanEndpoint(demo.body, b)) / (2.0 * kStep);
  }

  HandPathShares s;
  std::array<double, kNumHumanJoints> energy{};
  Eigen::Vector3d h_mean = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> h(circle.size());
  for (std::size_t i = 0; i < circle.size(); ++i) {
    for (int k = 0; k < kNumHumanJoints; ++k)
      energy[static_cast<std::size_t>(k)] += (J.col(k) * ((*circle[i])[k] - mean[k])).squaredNorm();
    h[i] = humanEndpoint(demo.body, *circle[i]);
    h_mean += h[i];
  }
  h_mean /= static_cast<double>(h.size());
  double spread2 = 0.0;
  for (const Eigen::Vector3d& p : h) spread2 += (p - h_mean).squaredNorm();
  s.spread_rms_m = std::sqrt(spread2 / static_cast<double>(h.size()));

  double total = 0.0;
  for (double e : energy) total += e;
  for (int k = 0; k < kNumHumanJoints; ++k) s.dof[static_cast<std::size_t>(k)] = energy[static_cast<std::size_t>(k)] / total;
  s.shoulder = s.dof[kHumanShoulderPitch] + s.dof[kHumanShoulderRoll];
  s.elbow = s.dof[kHumanElbowYaw] + s.dof[kHumanElbowRoll];
  s.forearm = s.dof[kHumanWristYaw];
  s.wrist = s.dof[kHumanWristFlex] + s.dof[kHumanWristDev];
  return s;
}

bool handReachable(const ArmModel& arm, const Eigen::Vector3d& p_target_TH, double tolerance_m, int n_starts,
                   std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  RetargetParams params;
  params.mu = 1e-9;  // a whisker of regularisation: the search is about reach, not posture
  RetargetData data;
  for (int s = 0; s < n_starts; ++s) {
    JointVector q0;
    for (int j = 0; j < kNumJoints; ++j) {
      // 53 random bits -> [0, 1): the same numbers on every standard library.
      const double u = static_cast<double>(rng() >> 11) * 0x1.0p-53;
      q0[j] = arm.q_min[j] + u * (arm.q_max[j] - arm.q_min[j]);
    }
    const JointVector& q = solveHandIk(arm, params, data, p_target_TH, q0, q0);
    if ((forwardKinematics(arm, data.arm, q) - p_target_TH).norm() <= tolerance_m) return true;
  }
  return false;
}

std::vector<GapFrame> embodimentGap(const ArmModel& arm, const std::vector<RetargetRow>& rows) {
  std::vector<GapFrame> out;
  ArmData d;
  for (const RetargetRow& r : rows) {
    if (r.flags & kRowHumanMissing) continue;
    GapFrame g;
    g.t_s = r.t_s;
    g.x_target = r.target.p_target_TH;
    g.q_clamp = clampToLimits(arm, r.target.q_target);
    g.p_clamp = forwardKinematics(arm, d, g.q_clamp);
    g.q_r = r.result.q_r;
    g.p_r = forwardKinematics(arm, d, g.q_r);
    g.inside_limits = (g.q_r.array() >= arm.q_min.array()).all() && (g.q_r.array() <= arm.q_max.array()).all();
    g.fallback = (r.flags & kRetargetFallback) != 0;
    if ((g.p_r - g.x_target).norm() > 0.01) g.reachable = handReachable(arm, g.x_target, 0.01);
    out.push_back(g);
  }
  return out;
}

GapSummary summariseGap(const std::vector<std::vector<GapFrame>>& sequences) {
  GapSummary s;
  std::vector<double> clamp_miss, r_miss, dq;
  std::array<std::vector<double>, kNumJoints> dq_joint;
  double speed2_r = 0.0, speed2_clamp = 0.0;
  int within = 0, recovered = 0, within_reachable = 0;
  for (const std::vector<GapFrame>& seq : sequences) {
    for (std::size_t i = 0; i < seq.size(); ++i) {
      const GapFrame& g = seq[i];
      const double mc = (g.p_clamp - g.x_target).norm(), mr = (g.p_r - g.x_target).norm();
      clamp_miss.push_back(mc);
      r_miss.push_back(mr);
      dq.push_back((g.q_r - g.q_clamp).norm());
      for (int j = 0; j < kNumJoints; ++j) dq_joint[static_cast<std::size_t>(j)].push_back(std::abs(g.q_r[j] - g.q_clamp[j]));
      within += mr <= 0.01;
      s.unreachable += !g.reachable;
      within_reachable += g.reachable && mr <= 0.01;
      if (mc > 0.01) {
        ++s.clamp_miss_frames;
        recovered += mr <= 0.01;
      }
      s.outside_limits += !g.inside_limits;
      s.fallbacks += g.fallback;
      // Speeds only between consecutive grid frames (a held gap is not motion).
      if (i > 0) {
        const double dt = g.t_s - seq[i - 1].t_s;
        if (dt > 0.0 && dt < 0.15) {
          speed2_r += ((g.q_r - seq[i - 1].q_r).head<4>() / dt).squaredNorm();
          speed2_clamp += ((g.q_clamp - seq[i - 1].q_clamp).head<4>() / dt).squaredNorm();
        }
      }
    }
  }
  s.frames = static_cast<int>(clamp_miss.size());
  if (s.frames == 0) return s;
  s.median_clamp_miss_m = median(clamp_miss);
  s.median_r_miss_m = median(r_miss);
  s.frac_r_within_1cm = static_cast<double>(within) / s.frames;
  s.frac_r_within_1cm_reachable =
      s.frames > s.unreachable ? static_cast<double>(within_reachable) / (s.frames - s.unreachable) : 1.0;
  s.median_dq_rad = median(dq);
  for (int j = 0; j < kNumJoints; ++j) s.median_abs_dq_joint[static_cast<std::size_t>(j)] = median(dq_joint[static_cast<std::size_t>(j)]);
  s.speed_ratio_shoulder_elbow = speed2_clamp > 0.0 ? std::sqrt(speed2_r / speed2_clamp) : 0.0;
  s.frac_recovered = s.clamp_miss_frames > 0 ? static_cast<double>(recovered) / s.clamp_miss_frames : 1.0;
  return s;
}

void writeGapCsv(const std::string& path, const std::vector<std::vector<GapFrame>>& sequences) {
  std::ofstream out(path);
  if (!out) throw UserError("cannot write " + path);
  out.precision(10);
  out << "seq,t_s,xt_x,xt_y,xt_z,pc_x,pc_y,pc_z,pr_x,pr_y,pr_z";
  for (const char* name : {"qc", "qr"})
    for (int j = 0; j < kNumJoints; ++j) out << ',' << name << '_' << j;
  out << '\n';
  for (std::size_t k = 0; k < sequences.size(); ++k) {
    for (const GapFrame& g : sequences[k]) {
      out << k << ',' << g.t_s;
      for (const Eigen::Vector3d* v : {&g.x_target, &g.p_clamp, &g.p_r})
        out << ',' << v->x() << ',' << v->y() << ',' << v->z();
      for (const JointVector* q : {&g.q_clamp, &g.q_r})
        for (int j = 0; j < kNumJoints; ++j) out << ',' << (*q)[j];
      out << '\n';
    }
  }
  if (!out) throw UserError("error while writing " + path);
}

}  // namespace nao::tools
