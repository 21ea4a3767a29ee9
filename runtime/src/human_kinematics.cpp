#include "nao/human_kinematics.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao {
namespace {

// atan2 answers in (-pi, pi]; a joint whose angle crosses +-pi (the forearm pointing straight
// out from a hanging upper arm, for ElbowYaw) would jump by 2 pi between frames, and clamped
// to NAO's limits that becomes a limit-to-limit jump. Take the 2 pi copy nearest the
// previous value instead (0 before the first measurement).
double unwrapNear(double raw, double previous) noexcept {
  return previous + std::remainder(raw - previous, 2.0 * 3.14159265358979323846);
}

// Shorter than this (m) a segment or axis has no direction.
constexpr double kMinLength_m = 1e-4;

bool usable(const SkeletonFrame& frame, int i) { return frame.ok[i] && frame.p_W[i].allFinite(); }

double clampUnit(double v) { return std::min(1.0, std::max(-1.0, v)); }

Eigen::Matrix3d rotX(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, c, -s, 0, s, c;
  return R;
}
Eigen::Matrix3d rotY(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Eigen::Matrix3d R;
  R << c, 0, s, 0, 1, 0, -s, 0, c;
  return R;
}
Eigen::Matrix3d rotZ(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Eigen::Matrix3d R;
  R << c, -s, 0, s, c, 0, 0, 0, 1;
  return R;
}

// Hand (palm) frame from the hand keypoints 0, 5, 9, 17 in the torso frame; false when a
// point is missing or the frame degenerate.
bool handFrame(const SkeletonFrame& frame, const Eigen::Matrix3d& R_WT, const Eigen::Vector3d& p_WT,
               Eigen::Matrix3d& R_TK, Eigen::Vector3d& p_TC) {
  for (int i : {kRHand0, kRHand5, kRHand9, kRHand17})
    if (!usable(frame, i)) return false;
  const Eigen::Vector3d x_W = frame.p_W[kRHand9] - frame.p_W[kRHand0];
  const double nx = x_W.norm();
  if (!(nx > kMinLength_m)) return false;
  const Eigen::Vector3d x_K = x_W / nx;
  Eigen::Vector3d z_W = frame.p_W[kRHand5] - frame.p_W[kRHand17];
  z_W -= x_K * x_K.dot(z_W);
  const double nz = z_W.norm();
  if (!(nz > kMinLength_m)) return false;
  const Eigen::Vector3d z_K = z_W / nz;
  const Eigen::Vector3d y_K = z_K.cross(x_K);
  Eigen::Matrix3d R_WK;
  R_WK.col(0) = x_K;
  R_WK.col(1) = y_K;
  R_WK.col(2) = z_K;
  R_TK.noalias() = R_WT.transpose() * R_WK;
  const Eigen::Vector3d c_W =
      0.25 * (frame.p_W[kRHand0] + frame.p_W[kRHand5] + frame.p_W[kRHand9] + frame.p_W[kRHand17]);
  p_TC.noalias() = R_WT.transpose() * (c_W - p_WT);
  return true;
}

}  // namespace

void resetHumanArm(HumanArmData& data) noexcept { data = HumanArmData{}; }

bool humanTorsoFrame(const SkeletonFrame& frame, Eigen::Matrix3d& R_WT, Eigen::Vector3d& p_WT) noexcept {
  if (!usable(frame, kRShoulder) || !usable(frame, kLShoulder)) return false;
  Eigen::Vector3d hip_W;
  if (usable(frame, kMidHip))
    hip_W = frame.p_W[kMidHip];
  else if (usable(frame, kRHip) && usable(frame, kLHip))
    hip_W = 0.5 * (frame.p_W[kRHip] + frame.p_W[kLHip]);
  else
    return false;
  const Eigen::Vector3d origin_W = 0.5 * (frame.p_W[kRShoulder] + frame.p_W[kLShoulder]);
  const Eigen::Vector3d up_W = origin_W - hip_W;
  const double n_up = up_W.norm();
  if (!(n_up > kMinLength_m)) return false;
  const Eigen::Vector3d z = up_W / n_up;
  Eigen::Vector3d y = frame.p_W[kLShoulder] - frame.p_W[kRShoulder];
  y -= z * z.dot(y);
  const double n_y = y.norm();
  if (!(n_y > kMinLength_m)) return false;
  y /= n_y;
  R_WT.col(0) = y.cross(z);
  R_WT.col(1) = y;
  R_WT.col(2) = z;
  p_WT = origin_W;
  return true;
}

const HumanArmData& humanArmKinematics(const HumanKinematicsConfig& config, HumanArmData& data,
                                        const SkeletonFrame& frame) noexcept {
  data.valid = false;
  data.hand_seen = false;
  data.flags = 0;
  for (int i : {kRShoulder, kLShoulder, kMidHip, kRHip, kLHip, kRElbow, kRWrist})
    if (frame.ok[i] && !frame.p_W[i].allFinite()) data.flags |= kHumanNotFinite;

  Eigen::Matrix3d R_WT;
  Eigen::Vector3d p_WT;
  if (!humanTorsoFrame(frame, R_WT, p_WT)) data.flags |= kHumanNoTorso;
  if (!usable(frame, kRShoulder) || !usable(frame, kRElbow) || !usable(frame, kRWrist)) data.flags |= kHumanNoArm;
  if (data.flags & kHumanInvalidMask) return data;

  const Eigen::Vector3d p_TS = R_WT.transpose() * (frame.p_W[kRShoulder] - p_WT);
  const Eigen::Vector3d p_TE = R_WT.transpose() * (frame.p_W[kRElbow] - p_WT);
  const Eigen::Vector3d p_TR = R_WT.transpose() * (frame.p_W[kRWrist] - p_WT);
  const double l_upper = (p_TE - p_TS).norm();
  const double l_forearm = (p_TR - p_TE).norm();
  if (!(l_upper > kMinLength_m) || !(l_forearm > kMinLength_m)) {
    data.flags |= kHumanNoArm;
    return data;
  }
  const Eigen::Vector3d u_T = (p_TE - p_TS) / l_upper;    // upper-arm direction
  const Eigen::Vector3d f_T = (p_TR - p_TE) / l_forearm;  // forearm direction

  // Shoulder: u = Ry(pitch) Rz(roll) e_x = (cos p cos r, sin r, -sin p cos r).
  HumanJointVector q = data.q;
  q[kHumanShoulderRoll] = std::asin(clampUnit(u_T.y()));
  if (std::sqrt(u_T.x() * u_T.x() + u_T.z() * u_T.z()) < config.shoulder_gimbal_cos)
    data.flags |= kHumanShoulderGimbal;
  else
    q[kHumanShoulderPitch] = unwrapNear(std::atan2(-u_T.z(), u_T.x()), q[kHumanShoulderPitch]);

  // Elbow: in the upper-arm frame before the humeral rotation, the forearm direction is
  // Rx(yaw) Rz(flex) e_x = (cos flex, sin flex cos yaw, sin flex sin yaw).
  const Eigen::Matrix3d R_TU0 = rotY(q[kHumanShoulderPitch]) * rotZ(q[kHumanShoulderRoll]);
  const Eigen::Vector3d f_U0 = R_TU0.transpose() * f_T;
  q[kHumanElbowRoll] = std::acos(clampUnit(f_U0.x()));
  if (q[kHumanElbowRoll] < config.elbow_straight_rad)
    data.flags |= kHumanElbowStraight;
  else
    q[kHumanElbowYaw] = unwrapNear(std::atan2(f_U0.z(), f_U0.y()), q[kHumanElbowYaw]);

  // Hand: R_F0K = Rx(wrist yaw) Rz(flex) Ry(dev) relative to the forearm frame before the
  // forearm rotation. Row 0 = (cos b cos c, -sin b, cos b sin c); column 1 =
  // (-sin b, cos a cos b, sin a cos b).
  Eigen::Matrix3d R_TK;
  Eigen::Vector3d p_TC;
  if (handFrame(frame, R_WT, p_WT, R_TK, p_TC)) {
    data.hand_seen = true;
    const Eigen::Matrix3d R_TF0 = R_TU0 * rotX(q[kHumanElbowYaw]) * rotZ(q[kHumanElbowRoll]);
    const Eigen::Matrix3d M = R_TF0.transpose() * R_TK;
    q[kHumanWristFlex] = std::asin(clampUnit(-M(0, 1)));
    if (std::cos(q[kHumanWristFlex]) < config.wrist_gimbal_cos) {
      data.flags |= kHumanWristGimbal;
    } else {
      q[kHumanWristDev] = unwrapNear(std::atan2(M(0, 2), M(0, 0)), q[kHumanWristDev]);
      q[kHumanWristYaw] = unwrapNear(std::atan2(M(2, 1), M(1, 1)), q[kHumanWristYaw]);
    }
    data.R_TK = R_TK;
    data.p_TH = p_TC;
  } else {
    data.flags |= kHumanNoHand;
    const double l_hand = config.hand_length_m > 0.0 ? config.hand_length_m : config.hand_to_forearm * l_forearm;
    data.p_TH = p_TR + l_hand * f_T;
  }

  data.p_WT = p_WT;
  data.R_WT = R_WT;
  data.p_TS = p_TS;
  data.p_TE = p_TE;
  data.p_TR = p_TR;
  data.p_SH_T = data.p_TH - p_TS;
  data.l_upper_m = l_upper;
  data.l_forearm_m = l_forearm;
  data.l_hand_m = (data.p_TH - p_TR).norm();
  data.d_h_m = config.scale_m > 0.0 ? config.scale_m : l_upper + l_forearm + data.l_hand_m;
  data.q = q;
  data.valid = true;
  return data;
}

Eigen::Vector3d scaleHumanEndpoint(double d_r_m, double d_h_m, const Eigen::Vector3d& p_SH_T) noexcept {
  // Not a plausible finite point (the shoulder) but NaN, so a retarget solve flags it as bad input.
  if (!(d_h_m > 0.0) || !std::isfinite(d_h_m) || !std::isfinite(d_r_m))
    return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  return (d_r_m / d_h_m) * p_SH_T;
}

}  // namespace nao
