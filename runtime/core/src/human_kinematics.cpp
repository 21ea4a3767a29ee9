#include "nao/human_kinematics.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Share of an azimuth's measured change it takes this frame (the continuity rule of the header):
// all of it from rho_exact on, rho / rho_exact below, none at or below rho_hold. The change is
// taken to the 2 pi copy of the measurement nearest the previous value: atan2 answers in
// (-pi, pi], and a joint whose angle crosses +-pi (ElbowYaw with the forearm straight out from a
// hanging upper arm) would otherwise jump by 2 pi, which NAO's limits turn into a
// limit-to-limit jump.
double azimuthGain(double rho, double rho_hold, double rho_exact) noexcept {
  if (rho >= rho_exact) return 1.0;
  if (rho <= rho_hold) return 0.0;
  return rho / rho_exact;
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

  // The continuity rule applies from the second measurement on; the first is exact.
  const bool arm_prior = data.arm_measured;
  auto gain = [&](double rho, double rho_hold, double rho_exact, bool prior) {
    const double g = prior ? azimuthGain(rho, rho_hold, rho_exact) : (rho <= rho_hold ? 0.0 : 1.0);
    if (g > 0.0 && g < 1.0) data.flags |= kHumanNearPole;
    return g;
  };
  // An angle measured in a frame that itself turned since the previous measurement (ElbowYaw in
  // the upper arm's frame Ry(pitch) Rz(roll), WristYaw in the forearm's) is continued from its
  // previous value carried along by that frame's twist about the segment (the twist part of a
  // swing-twist split of the frame's motion): where the shoulder passes its pole, ShoulderPitch
  // turns by up to pi within a frame and ElbowYaw with it, and the carried value decides which
  // 2 pi copy of the measurement is the continuous one. The twist is the body rate's component
  // along the segment integrated over the coordinates' own changes (taken at their mid-point),
  // so it turns the way the pitch turned (through the front), never the other way round.
  const HumanJointVector q_prev = data.q;

  // Shoulder: u = Ry(pitch) Rz(roll) e_x = (cos p cos r, sin r, -sin p cos r). Pitch on its
  // principal value: its cut (the arm pointing backwards) is out of any arm's reach, and a pass
  // by the pole (the arm straight out sideways) then turns it through the front, as NAO must.
  HumanJointVector q = data.q;
  q[kHumanShoulderRoll] = std::asin(clampUnit(u_T.y()));
  const double rho_shoulder = std::sqrt(u_T.x() * u_T.x() + u_T.z() * u_T.z());
  if (rho_shoulder < config.shoulder_gimbal_cos) data.flags |= kHumanShoulderGimbal;
  const double g_pitch = gain(rho_shoulder, config.shoulder_gimbal_cos, config.shoulder_exact_cos, arm_prior);
  q[kHumanShoulderPitch] += g_pitch * (std::atan2(-u_T.z(), u_T.x()) - q[kHumanShoulderPitch]);

  // Elbow: in the upper-arm frame before the humeral rotation, the forearm direction is
  // Rx(yaw) Rz(flex) e_x = (cos flex, sin flex cos yaw, sin flex sin yaw).
  const Eigen::Matrix3d R_TU0 = rotY(q[kHumanShoulderPitch]) * rotZ(q[kHumanShoulderRoll]);
  const Eigen::Vector3d f_U0 = R_TU0.transpose() * f_T;
  q[kHumanElbowRoll] = std::acos(clampUnit(f_U0.x()));
  if (q[kHumanElbowRoll] < config.elbow_straight_rad) data.flags |= kHumanElbowStraight;
  const double g_yaw = gain(std::sin(q[kHumanElbowRoll]), std::sin(config.elbow_straight_rad),
                            std::sin(config.elbow_exact_rad), arm_prior);
  const double d_pitch = q[kHumanShoulderPitch] - q_prev[kHumanShoulderPitch];
  const double d_roll = q[kHumanShoulderRoll] - q_prev[kHumanShoulderRoll];
  const double roll_mid = q_prev[kHumanShoulderRoll] + 0.5 * d_roll;
  // Twist of Ry(pitch) Rz(roll) about its x axis: sin(roll) d pitch.
  const double yaw_from = q_prev[kHumanElbowYaw] - (arm_prior ? std::sin(roll_mid) * d_pitch : 0.0);
  q[kHumanElbowYaw] = yaw_from + g_yaw * std::remainder(std::atan2(f_U0.z(), f_U0.y()) - yaw_from, 2.0 * kPi);

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
    const double rho_wrist = std::cos(q[kHumanWristFlex]);
    if (rho_wrist < config.wrist_gimbal_cos) data.flags |= kHumanWristGimbal;
    const double g_wrist = gain(rho_wrist, config.wrist_gimbal_cos, config.wrist_exact_cos, data.hand_measured);
    q[kHumanWristDev] += g_wrist * std::remainder(std::atan2(M(0, 2), M(0, 0)) - q[kHumanWristDev], 2.0 * kPi);
    // Twist of the forearm frame R_TU0 Rx(yaw) Rz(flex) about its x axis.
    const double d_yaw = q[kHumanElbowYaw] - q_prev[kHumanElbowYaw];
    const double yaw_mid = q_prev[kHumanElbowYaw] + 0.5 * d_yaw;
    const double flex_mid = 0.5 * (q_prev[kHumanElbowRoll] + q[kHumanElbowRoll]);
    const double forearm_twist =
        std::cos(flex_mid) * (std::sin(roll_mid) * d_pitch + d_yaw) +
        std::sin(flex_mid) * (std::cos(yaw_mid) * std::cos(roll_mid) * d_pitch + std::sin(yaw_mid) * d_roll);
    const double wrist_from = q_prev[kHumanWristYaw] - (data.hand_measured ? forearm_twist : 0.0);
    q[kHumanWristYaw] = wrist_from + g_wrist * std::remainder(std::atan2(M(2, 1), M(1, 1)) - wrist_from, 2.0 * kPi);
    data.hand_measured = true;
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
  data.arm_measured = true;
  return data;
}

Eigen::Vector3d scaleHumanEndpoint(double d_r_m, double d_h_m, const Eigen::Vector3d& p_SH_T) noexcept {
  // Not a plausible finite point (the shoulder) but NaN, so a retarget solve flags it as bad input.
  if (!(d_h_m > 0.0) || !std::isfinite(d_h_m) || !std::isfinite(d_r_m))
    return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  return (d_r_m / d_h_m) * p_SH_T;
}

}  // namespace nao
