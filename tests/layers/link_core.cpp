// Links nao_core alone (layer_core_links): the tick's code needs nothing but Eigen and the C++
// runtime. Uses a piece of each part so the linker pulls them in.
#include "nao/attention_ring.hpp"
#include "nao/controller.hpp"

int main() {
  nao::ArmModel arm{};
  arm.q_min.setConstant(-1.0);
  arm.q_max.setConstant(1.0);
  arm.v_max.setConstant(1.0);
  for (int j = 0; j < nao::kNumJoints; ++j) {
    arm.p_PJ[static_cast<std::size_t>(j)].setZero();
    arm.R_PJ[static_cast<std::size_t>(j)].setIdentity();
    arm.axis_J[static_cast<std::size_t>(j)] = Eigen::Vector3d::UnitZ();
  }
  arm.p_WH.setZero();
  arm.R_WH.setIdentity();
  nao::ArmData kin;
  nao::JointVector q_cmd;
  nao::limitCommand(arm, 0.1, nao::JointVector::Zero(), nao::JointVector::Ones(), q_cmd);
  const Eigen::Vector3d p = nao::forwardKinematics(arm, kin, q_cmd);
  nao::RetargetData retarget;
  nao::resetRetarget(arm, retarget, q_cmd);
  const nao::RetargetResult& r = nao::solveRetarget(arm, nao::RetargetParams{}, retarget, p, q_cmd);
  return nao::runCodeIndex(nao::ModelRunCodes{}, r.q_r) == -1 && nao::attentionReadName(nao::AttentionRead::kOk) ? 0 : 1;
}
