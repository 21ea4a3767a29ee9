#include "nao/kinematics.hpp"

#include <Eigen/Geometry>

namespace nao {

const Eigen::Vector3d& forwardKinematics(const ArmModel& model, ArmData& data, const JointVector& q) {
  data.q = q;
  Eigen::Matrix3d R_TP = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p_TP = Eigen::Vector3d::Zero();
  for (int j = 0; j < kNumJoints; ++j) {
    // Joint frame before its own rotation, then the rotation about its axis.
    const Eigen::Matrix3d R_TJ0 = R_TP * model.R_PJ[j];
    data.p_TJ[j].noalias() = p_TP + R_TP * model.p_PJ[j];
    data.a_TJ[j].noalias() = R_TJ0 * model.axis_J[j];
    data.R_TJ[j].noalias() = R_TJ0 * Eigen::AngleAxisd(q[j], model.axis_J[j]).toRotationMatrix();
    R_TP = data.R_TJ[j];
    p_TP = data.p_TJ[j];
  }
  data.p_TH.noalias() = p_TP + R_TP * model.p_WH;
  data.R_TH.noalias() = R_TP * model.R_WH;
  data.u_TH = data.R_TH.col(0);
  return data.p_TH;
}

const ArmJacobian& handJacobian(const ArmModel&, ArmData& data) {
  for (int j = 0; j < kNumJoints; ++j) {
    const Eigen::Vector3d& a = data.a_TJ[j];
    data.Jp_TH.col(j) = a.cross(data.p_TH - data.p_TJ[j]);
    data.Ju_TH.col(j) = a.cross(data.u_TH);
    data.Jw_TH.col(j) = a;
  }
  return data.Jp_TH;
}

}  // namespace nao
