#include "nao/arm_model.hpp"

namespace nao {

double robotScale(const ArmModel& model) {
  // RShoulderPitch's origin is the shoulder itself (relative to the torso), not a link.
  double d = model.p_WH.norm();
  for (int j = 1; j < kNumJoints; ++j) d += model.p_PJ[j].norm();
  return d;
}

JointVector clampToLimits(const ArmModel& model, const JointVector& q) {
  return q.cwiseMax(model.q_min).cwiseMin(model.q_max);
}

}  // namespace nao
