// Human arm kinematics from one 3D skeleton frame: torso frame, right-arm points, joint
// angles in NAO's convention, the human scale constant d_h and the scaled endpoint
// p_r = (d_r / d_h) * p_h (paper eqs. 1-2). Fixed-size, allocation-free, never throws: it
// runs on every 100 ms tick of the runtime.
//
// Frames and points (docs/notation.md): W world (calibration) frame, T the human torso frame,
// S right shoulder, E right elbow, R right wrist, H the hand endpoint (the human point that
// corresponds to NAO's hand point `r_hand`), K the hand (palm) frame built from the hand keypoints.
//
// Torso frame T (same axes as NAO's torso: x forward, y left, z up):
//   origin  = shoulder midpoint (RShoulder + LShoulder) / 2;
//   z       = unit(origin - hip centre), hip centre = MidHip, else (RHip + LHip) / 2;
//   y       = unit(LShoulder - RShoulder with its z component removed);
//   x       = y × z.
// The neck point is not used (it differs between BODY_25 and BODY_25B), so the frame is the
// same for both layouts and follows a subject who walks or turns.
//
// Human arm chain = NAO's chain with human link lengths (docs/synth.md, "Angle mapping"):
//   R_TU = Ry(q0) Rz(q1) Rx(q2)                upper arm: ShoulderPitch, ShoulderRoll,
//                                               humeral rotation ≙ ElbowYaw
//   p_TE = p_TS + R_TU (l_upper, 0, 0)
//   R_TF = R_TU Rz(q3) Rx(q4)                   elbow flexion ≙ ElbowRoll,
//                                               forearm rotation ≙ WristYaw (pronation < 0)
//   p_TR = p_TE + R_TF (l_forearm, 0, 0)
//   R_TK = R_TF Rz(q5) Ry(q6)                   wrist flexion (towards the palm > 0),
//                                               wrist deviation (ulnar, towards the little finger > 0)
// At q = 0 the arm points straight forward (torso +x), the palm faces the body's midline
// (+y), the thumb is up (+z): NAO's zero pose. The hand frame K from the keypoints: x_K from
// hand point 0 (wrist) to 9 (middle-finger knuckle); z_K from the little-finger knuckle 17
// towards the index knuckle 5, orthogonalised; y_K = z_K × x_K (palm normal).
//
// Continuity. Each stage of the chain is a direction on a sphere read as (polar angle, azimuth):
// the upper arm (ShoulderRoll, ShoulderPitch), the forearm in the upper arm's frame (ElbowRoll,
// ElbowYaw), the hand in the forearm's frame (wrist flexion, WristYaw with the deviation). An
// azimuth is undefined at its pole (the upper arm along the torso's y axis, a straight elbow,
// the wrist flexed 90 deg) and amplifies the measurement's noise by 1 / rho near it, rho the
// direction's distance from the pole (cos roll, sin flexion, cos wrist flexion); passing by the
// pole, the exact angles swing by up to pi within a frame. So, from the second measured frame
// on, an azimuth moves from its previous value by rho / rho_exact of its measured change where
// rho < rho_exact (never more than 1 / rho_exact times the direction's own change, and not at
// all below the hold threshold), and by all of it elsewhere; the measured change is taken on
// the 2 pi copy nearest the previous value (ShoulderPitch, whose cut lies behind the back
// where no arm goes, on its principal value, so that a pass by the pole turns it through the
// front where NAO can follow). Where rho >= rho_exact the angles are the exact ones above;
// near a pole they trade exactness for continuity, and the next stage, measured relative to
// the previous one's angles, absorbs the difference (the chain keeps the measured forearm and
// hand directions).
#pragma once

#include "nao/arm_model.hpp"
#include "nao/body25.hpp"

#include <Eigen/Core>

#include <cstdint>

namespace nao {

/// Human arm DoFs: the five NAO-mapped ones in NAO's joint order, then the two NAO lacks.
inline constexpr int kNumHumanJoints = 7;
using HumanJointVector = Eigen::Matrix<double, kNumHumanJoints, 1>;
enum HumanJoint : int {
  kHumanShoulderPitch = 0, kHumanShoulderRoll, kHumanElbowYaw, kHumanElbowRoll, kHumanWristYaw,
  kHumanWristFlex, kHumanWristDev,
};
inline constexpr const char* kHumanJointNames[kNumHumanJoints] = {
    "h_shoulder_pitch", "h_shoulder_roll", "h_elbow_yaw", "h_elbow_roll", "h_wrist_yaw", "h_wrist_flex", "h_wrist_dev"};

/// Bits of HumanArmData::flags. kHumanNoTorso / kHumanNoArm / kHumanNotFinite make the frame
/// invalid (nothing measured); the others mark angles that were held, not measured.
enum HumanFlag : std::uint32_t {
  kHumanNoTorso = 1u << 0,        ///< a shoulder or the hips missing, or the torso degenerate
  kHumanNoArm = 1u << 1,          ///< RShoulder, RElbow or RWrist missing, or a zero-length segment
  kHumanNotFinite = 1u << 2,      ///< a needed point is NaN/inf
  kHumanNoHand = 1u << 3,         ///< hand points 0/5/9/17 not all seen (or degenerate): wrist yaw,
                                  ///< flexion and deviation held; endpoint from the forearm
  kHumanElbowStraight = 1u << 4,  ///< elbow flexion below the threshold: ElbowYaw held
  kHumanShoulderGimbal = 1u << 5, ///< upper arm along the torso's y axis: ShoulderPitch held
  kHumanWristGimbal = 1u << 6,    ///< wrist flexion near ±90°: wrist yaw and deviation held
  kHumanNearPole = 1u << 7,       ///< an azimuth moved by only a part of its measured change (continuity)
};
inline constexpr std::uint32_t kHumanInvalidMask = kHumanNoTorso | kHumanNoArm | kHumanNotFinite;

/// Fixed settings of the human kinematics (configure time; never changed by the functions).
struct HumanKinematicsConfig {
  /// Below this elbow flexion (rad) the humeral rotation is undefined and held.
  double elbow_straight_rad = 3.0 * 3.14159265358979323846 / 180.0;
  /// Below this |cos(ShoulderRoll)| the shoulder pitch is undefined and held.
  double shoulder_gimbal_cos = 0.02;
  /// Below this |cos(wrist flexion)| the wrist yaw / deviation split is undefined and held.
  double wrist_gimbal_cos = 0.02;
  /// rho_exact of the continuity rule (file comment): from these distances from the poles on,
  /// the angles are exact: |cos(ShoulderRoll)| (0.26: the upper arm within 15° of pointing
  /// straight sideways), elbow flexion (6°) and |cos(wrist flexion)| (0.26: flexed 75°).
  double shoulder_exact_cos = 0.26;
  double elbow_exact_rad = 6.0 * 3.14159265358979323846 / 180.0;
  double wrist_exact_cos = 0.26;
  /// Hand segment length (wrist -> hand endpoint) used when the hand is not seen, m. When
  /// <= 0, hand_to_forearm * forearm length of the current frame is used.
  double hand_length_m = 0.0;
  /// Hand segment / forearm length ratio for the fallback above (Winter's proportions:
  /// hand-point centroid 0.043 H / forearm 0.146 H, docs/synth.md).
  double hand_to_forearm = 0.29;
  /// Fixed human scale d_h, m (e.g. the median over the demonstration, toolchain
  /// estimateHumanArmLengths). When <= 0 the per-frame sum of the link lengths is used.
  double scale_m = 0.0;
};

/// Everything humanArmKinematics writes, plus the held angles it needs across frames. Build
/// one per subject stream (configure time); reset with resetHumanArm.
struct HumanArmData {
  std::uint32_t flags = kHumanNoTorso;  ///< HumanFlag bits of the last frame
  bool valid = false;      ///< torso and arm measured: angles q[0..3], points and p_SH_T usable
  bool hand_seen = false;  ///< hand frame measured: q[4..6] measured this frame
  bool arm_measured = false;   ///< q[0..3] hold a measurement (the continuity rule applies to them)
  bool hand_measured = false;  ///< q[4..6] hold a measurement

  Eigen::Matrix3d R_WT = Eigen::Matrix3d::Identity();  ///< torso frame orientation in the world
  Eigen::Vector3d p_WT = Eigen::Vector3d::Zero();      ///< torso origin (shoulder midpoint), world, m
  Eigen::Vector3d p_TS = Eigen::Vector3d::Zero();      ///< right shoulder in the torso frame, m
  Eigen::Vector3d p_TE = Eigen::Vector3d::Zero();      ///< right elbow, torso frame, m
  Eigen::Vector3d p_TR = Eigen::Vector3d::Zero();      ///< right wrist, torso frame, m
  Eigen::Vector3d p_TH = Eigen::Vector3d::Zero();      ///< hand endpoint, torso frame, m
  Eigen::Vector3d p_SH_T = Eigen::Vector3d::Zero();    ///< p_h: endpoint relative to the shoulder, torso axes, m
  Eigen::Matrix3d R_TK = Eigen::Matrix3d::Identity();  ///< hand (palm) frame in the torso (when hand_seen)

  double l_upper_m = 0.0;    ///< |p_TE - p_TS| this frame
  double l_forearm_m = 0.0;  ///< |p_TR - p_TE| this frame
  double l_hand_m = 0.0;     ///< |p_TH - p_TR| this frame (measured or the fallback)
  double d_h_m = 0.0;        ///< human scale constant used this frame (config.scale_m or the sum)

  HumanJointVector q = HumanJointVector::Zero();  ///< angles, rad (held values where flagged)
};

/// Forgets the held angles and marks the data invalid. Real-time safe.
void resetHumanArm(HumanArmData& data) noexcept;

/// Torso frame of `frame` (see the file comment). Writes R_WT / p_WT and returns true when
/// both shoulders and MidHip (or both hips) are valid, finite and not degenerate; otherwise
/// leaves them untouched and returns false. Real-time safe.
bool humanTorsoFrame(const SkeletonFrame& frame, Eigen::Matrix3d& R_WT, Eigen::Vector3d& p_WT) noexcept;

/// Human right-arm kinematics of one skeleton frame (world-frame points, m).
/// Writes into `data`: flags, valid, hand_seen, the torso frame, the arm points in it, the
/// hand frame, the link lengths, d_h, p_h = p_SH_T and the joint angles q (HumanJoint order,
/// rad; the first five in NAO's convention; continuous from frame to frame by the rule of the
/// file comment: exact away from the poles, the first measurement exact everywhere). Angles
/// that cannot be measured keep their previous value and are flagged; when the frame is invalid
/// nothing but `flags` and `valid` changes. Never invents a point, never produces NaN. Returns
/// `data`. Real-time safe.
const HumanArmData& humanArmKinematics(const HumanKinematicsConfig& config, HumanArmData& data,
                                        const SkeletonFrame& frame) noexcept;

/// Paper eq. 2: p_r = (d_r / d_h) * p_h, the robot's endpoint target relative to its shoulder
/// in the torso frame (m). Returns NaN (which solveRetarget flags as bad input) when d_h <= 0
/// or a scale is non-finite. Real-time safe.
Eigen::Vector3d scaleHumanEndpoint(double d_r_m, double d_h_m, const Eigen::Vector3d& p_SH_T) noexcept;

}  // namespace nao
