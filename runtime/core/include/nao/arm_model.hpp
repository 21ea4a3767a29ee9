// ArmModel: the immutable description of the NAO V6 right arm, read once from a URDF
// (nao/arm_model_io.hpp, nao_io) at configure time.
//
// Notation (docs/notation.md): p_AB is the position of point/frame B in frame A,
// R_AB the orientation of frame B in frame A. T = torso, J = a joint frame,
// P = the parent joint frame, C = a link's centre of mass, W = wrist (last joint),
// H = the hand point (NAOqi's "RArm" effector).
#pragma once

#include <Eigen/Core>

#include <array>
#include <stdexcept>
#include <string>

namespace nao {

/// Number of arm joints J, in the order of kJointNames everywhere in the code and files.
inline constexpr int kNumJoints = 5;

using JointVector = Eigen::Matrix<double, kNumJoints, 1>;

inline constexpr std::array<const char*, kNumJoints> kJointNames = {
    "RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw"};
inline constexpr const char* kTorsoLink = "torso";
inline constexpr const char* kHandLink = "r_hand";

/// Mass properties of one link, in that link's frame (the frame of the joint that moves it).
struct LinkInertial {
  double mass = 0.0;                              ///< kg
  Eigen::Vector3d p_LC = Eigen::Vector3d::Zero();  ///< CoM in the link frame, m
  Eigen::Matrix3d I_C = Eigen::Matrix3d::Zero();   ///< inertia about the CoM, link-frame axes, kg m^2
};

/// The arm as the URDF describes it: fixed-size, built at configure time, never changed after.
/// Joint j's frame sits at p_PJ[j] / R_PJ[j] in the frame of joint j-1 (the torso for j = 0)
/// and turns about axis_J[j] (unit, in its own frame) by q_j.
struct ArmModel {
  std::array<Eigen::Vector3d, kNumJoints> p_PJ;  ///< joint origins in the parent joint frame, m
  std::array<Eigen::Matrix3d, kNumJoints> R_PJ;  ///< joint origin orientations in the parent frame
  std::array<Eigen::Vector3d, kNumJoints> axis_J;  ///< unit rotation axes in the joint frame
  JointVector q_min;  ///< lower position limits, rad
  JointVector q_max;  ///< upper position limits, rad
  JointVector v_max;  ///< velocity limits, rad/s
  JointVector tau_max;  ///< effort limits, N m
  std::array<LinkInertial, kNumJoints> link;  ///< the link each joint moves (hand mass on the last)
  Eigen::Vector3d p_WH;  ///< hand point in the wrist (last joint) frame, m
  Eigen::Matrix3d R_WH;  ///< hand frame orientation in the wrist frame
};

/// An arm description that cannot be used as the NAO arm (a URDF, nao/arm_model_io.hpp, or limits
/// the simulated motors cannot hold): the message names the source and the problem.
class ArmModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Robot scale constant d_r of paper eq. 1: the sum of the arm's link lengths from the
/// shoulder to the hand point (joint-origin offsets after RShoulderPitch, plus the hand
/// offset), m. Real-time safe.
double robotScale(const ArmModel& model);

/// q clamped to the model's position limits. Real-time safe.
JointVector clampToLimits(const ArmModel& model, const JointVector& q);

}  // namespace nao
