// Kinematics: checked against the reference numbers, against KDL (an independent
// implementation reading the same URDF) and against finite differences of itself.
#include "nao/kinematics.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>

#include <random>

using namespace nao;
using nao::test::kUrdfPath;

TEST_CASE("at the zero pose the joints and the hand sit where NAO's documented lengths put them") {
  const ArmModel m = loadArmModel(kUrdfPath);
  ArmData d;
  const Eigen::Vector3d& p_TH = forwardKinematics(m, d, JointVector::Zero());
  CHECK_MESSAGE((p_TH - Eigen::Vector3d(0.21870, -0.11300, 0.08769)).norm() < 1e-6, "hand at " << p_TH.transpose());
  CHECK((d.p_TJ[0] - Eigen::Vector3d(0.0, -0.098, 0.100)).norm() < 1e-12);     // shoulder
  CHECK((d.p_TJ[2] - Eigen::Vector3d(0.105, -0.113, 0.100)).norm() < 1e-12);   // elbow
  CHECK((d.p_TJ[4] - Eigen::Vector3d(0.16095, -0.113, 0.100)).norm() < 1e-12); // wrist
  CHECK(d.u_TH.isApprox(Eigen::Vector3d::UnitX()));
}

TEST_CASE("joint signs follow NAOqi: +ShoulderPitch lowers the arm, -ShoulderRoll moves it outward") {
  const ArmModel m = loadArmModel(kUrdfPath);
  ArmData d;
  JointVector q = JointVector::Zero();
  q[0] = 1.5707963267948966;  // arm hanging down
  forwardKinematics(m, d, q);
  CHECK(d.p_TH.z() < 0.100 - 0.2);
  q.setZero();
  q[1] = -1.0;
  const double y_out = forwardKinematics(m, d, q).y();
  CHECK(y_out < -0.113 - 0.1);
  q.setZero();
  q[3] = 1.5;  // +ElbowRoll bends the forearm inward (+y)
  CHECK(forwardKinematics(m, d, q).y() > -0.113 + 0.05);
}

TEST_CASE("forward kinematics agrees with KDL on the same URDF within 1e-9 m at 1000 random poses") {
  const ArmModel m = loadArmModel(kUrdfPath);
  KDL::Tree tree;
  REQUIRE(kdl_parser::treeFromFile(kUrdfPath, tree));
  KDL::Chain chain;
  REQUIRE(tree.getChain(kTorsoLink, kHandLink, chain));
  REQUIRE(chain.getNrOfJoints() == static_cast<unsigned>(kNumJoints));
  // KDL orders the chain's movable joints from the root: the same order as ours.
  int k = 0;
  for (const KDL::Segment& s : chain.segments)
    if (s.getJoint().getType() != KDL::Joint::None) CHECK(s.getJoint().getName() == kJointNames[k++]);

  KDL::ChainFkSolverPos_recursive fk(chain);
  KDL::JntArray q_kdl(kNumJoints);
  ArmData d;
  std::mt19937_64 rng(20261121);
  double worst = 0.0;
  for (int i = 0; i < 1000; ++i) {
    const JointVector q = nao::test::randomPose(m, rng);
    for (int j = 0; j < kNumJoints; ++j) q_kdl(j) = q[j];
    KDL::Frame X;
    REQUIRE(fk.JntToCart(q_kdl, X) >= 0);
    forwardKinematics(m, d, q);
    const Eigen::Vector3d p_kdl(X.p.x(), X.p.y(), X.p.z());
    worst = std::max(worst, (d.p_TH - p_kdl).norm());
    Eigen::Matrix3d R_kdl;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) R_kdl(r, c) = X.M(r, c);
    CHECK_MESSAGE((d.R_TH - R_kdl).cwiseAbs().maxCoeff() < 1e-9, "hand orientation differs at q = " << q.transpose());
  }
  CHECK_MESSAGE(worst < 1e-9, "largest hand position difference from KDL: " << worst << " m");
}

TEST_CASE("the analytic Jacobian agrees with central finite differences within 1e-6 at 1000 random poses") {
  const ArmModel m = loadArmModel(kUrdfPath);
  ArmData d, d_plus, d_minus;
  std::mt19937_64 rng(7);
  constexpr double h = 1e-6;
  double worst_p = 0.0, worst_u = 0.0;
  for (int i = 0; i < 1000; ++i) {
    const JointVector q = nao::test::randomPose(m, rng);
    forwardKinematics(m, d, q);
    handJacobian(m, d);
    for (int j = 0; j < kNumJoints; ++j) {
      JointVector qp = q, qm = q;
      qp[j] += h;
      qm[j] -= h;
      forwardKinematics(m, d_plus, qp);
      forwardKinematics(m, d_minus, qm);
      const Eigen::Vector3d dp = (d_plus.p_TH - d_minus.p_TH) / (2 * h);
      const Eigen::Vector3d du = (d_plus.u_TH - d_minus.u_TH) / (2 * h);
      worst_p = std::max(worst_p, (d.Jp_TH.col(j) - dp).cwiseAbs().maxCoeff());
      worst_u = std::max(worst_u, (d.Ju_TH.col(j) - du).cwiseAbs().maxCoeff());
    }
  }
  CHECK_MESSAGE(worst_p < 1e-6, "position Jacobian: largest difference " << worst_p);
  CHECK_MESSAGE(worst_u < 1e-6, "pointing-direction Jacobian: largest difference " << worst_u);
}

TEST_CASE("the angular Jacobian columns are the joint axes and the wrist does not move the hand point's pointing axis") {
  const ArmModel m = loadArmModel(kUrdfPath);
  ArmData d;
  std::mt19937_64 rng(11);
  const JointVector q = nao::test::randomPose(m, rng);
  forwardKinematics(m, d, q);
  handJacobian(m, d);
  for (int j = 0; j < kNumJoints; ++j) CHECK(d.Jw_TH.col(j).isApprox(d.a_TJ[j]));
  // RWristYaw turns about the hand's own x axis, so the pointing direction is blind to it.
  CHECK(d.Ju_TH.col(4).norm() < 1e-12);
}
