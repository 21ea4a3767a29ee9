// Forward kinematics and the analytic hand Jacobian of the NAO arm (fixed-size, allocation-free).
#pragma once

#include "nao/arm_model.hpp"

#include <Eigen/Core>

#include <array>

namespace nao {

using ArmJacobian = Eigen::Matrix<double, 3, kNumJoints>;

/// Everything the kinematics functions write. Built once (configure time); the functions
/// below only overwrite its fields, so it never allocates.
struct ArmData {
  JointVector q = JointVector::Zero();               ///< pose the fields below belong to, rad
  std::array<Eigen::Matrix3d, kNumJoints> R_TJ;      ///< joint frame orientations in the torso
  std::array<Eigen::Vector3d, kNumJoints> p_TJ;      ///< joint frame origins in the torso, m
  std::array<Eigen::Vector3d, kNumJoints> a_TJ;      ///< joint axes in the torso (unit)
  Eigen::Matrix3d R_TH = Eigen::Matrix3d::Identity();  ///< hand frame orientation in the torso
  Eigen::Vector3d p_TH = Eigen::Vector3d::Zero();    ///< hand point in the torso, m
  Eigen::Vector3d u_TH = Eigen::Vector3d::UnitX();   ///< hand pointing direction (hand x axis), unit
  ArmJacobian Jp_TH = ArmJacobian::Zero();           ///< d p_TH / d q, m/rad
  ArmJacobian Ju_TH = ArmJacobian::Zero();           ///< d u_TH / d q, 1/rad
  ArmJacobian Jw_TH = ArmJacobian::Zero();           ///< hand angular velocity per joint rate (= a_TJ)
};

/// Forward kinematics of every joint frame and the hand point at pose q (rad, joint order of
/// kJointNames). Writes q, R_TJ, p_TJ, a_TJ, R_TH, p_TH and u_TH into `data`; returns p_TH.
/// Real-time safe.
const Eigen::Vector3d& forwardKinematics(const ArmModel& model, ArmData& data, const JointVector& q);

/// Analytic geometric Jacobian of the hand at the pose of the last forwardKinematics call:
/// position rows Jp_TH (column j = a_j x (p_TH - p_j)), pointing-direction rows Ju_TH
/// (a_j x u_TH) and angular rows Jw_TH (a_j). Writes them into `data`; returns Jp_TH.
/// Real-time safe.
const ArmJacobian& handJacobian(const ArmModel& model, ArmData& data);

}  // namespace nao
