#include "nao/arm_model_io.hpp"
#include "nao/text_guard.hpp"
#include "nao/urdf_reader.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace nao {
namespace {

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw ArmModelError(origin + ": " + what);
}

Eigen::Vector3d toEigen(const urdf::Vector3& v) { return {v.x, v.y, v.z}; }

// A robot this size has every offset within a metre; 10 m leaves room for any arm while still
// refusing numbers (1e308) that only break the kinematics later, on every tick.
constexpr double kMaxOffset_m = 10.0;
// A revolute joint's limits lie within one turn each way; speeds and torques within these.
constexpr double kMaxLimit_rad = 2.0 * 3.14159265358979323846;
constexpr double kMaxVelocity_rads = 1e3;
constexpr double kMaxEffort_Nm = 1e4;

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

// A pose from the URDF (joint or inertial origin): finite and of plausible size.
void checkPose(const urdf::Pose& pose, const std::string& origin, const std::string& what) {
  const Eigen::Vector3d p = toEigen(pose.position);
  if (!p.allFinite() || p.cwiseAbs().maxCoeff() >= kMaxOffset_m)
    fail(origin, what + " origin xyz=\"" + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) +
                     "\" is not finite or not within " + num(kMaxOffset_m) + " m");
  double x, y, z, w;
  pose.rotation.getQuaternion(x, y, z, w);
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z) || !std::isfinite(w) ||
      !(std::abs(x) + std::abs(y) + std::abs(z) + std::abs(w) > 0.0))
    fail(origin, what + " origin rpy is not a finite rotation");
}

Eigen::Matrix3d toEigen(const urdf::Rotation& r) {
  double x, y, z, w;
  r.getQuaternion(x, y, z, w);
  return Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
}

const char* typeName(int type) {
  switch (type) {
    case urdf::Joint::REVOLUTE: return "revolute";
    case urdf::Joint::CONTINUOUS: return "continuous";
    case urdf::Joint::PRISMATIC: return "prismatic";
    case urdf::Joint::FLOATING: return "floating";
    case urdf::Joint::PLANAR: return "planar";
    case urdf::Joint::FIXED: return "fixed";
    default: return "unknown";
  }
}

LinkInertial readInertial(const urdf::Link& link, const std::string& origin) {
  if (!link.inertial) fail(origin, "link '" + link.name + "' has no <inertial>; the simulator needs its mass");
  const urdf::Inertial& in = *link.inertial;
  checkPose(in.origin, origin, "link '" + link.name + "' <inertial>");
  if (!(in.mass > 0.0) || !std::isfinite(in.mass))
    fail(origin, "link '" + link.name + "' has mass " + std::to_string(in.mass) + "; expected > 0");
  LinkInertial out;
  out.mass = in.mass;
  out.p_LC = toEigen(in.origin.position);
  Eigen::Matrix3d I;
  I << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
  // The URDF gives the inertia in the <inertial> origin frame; express it in link axes.
  const Eigen::Matrix3d R_LI = toEigen(in.origin.rotation);
  out.I_C = R_LI * I * R_LI.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(out.I_C);
  if (!(eig.eigenvalues().minCoeff() > 0.0))
    fail(origin, "link '" + link.name + "' has an inertia that is not positive definite");
  return out;
}

}  // namespace

ArmModel loadArmModel(const std::string& urdf_path) {
  std::ifstream file(urdf_path);
  if (!file) fail(urdf_path, "cannot open the URDF file (does it exist and is it readable?)");
  std::ostringstream text;
  text << file.rdbuf();
  if (!file && !file.eof()) fail(urdf_path, "cannot read the URDF file");
  return parseArmModel(text.str(), urdf_path);
}

ArmModel parseArmModel(const std::string& urdf_xml, const std::string& origin) {
  // TinyXML recurses per element and trusts UTF-8 lead bytes: bound the text first.
  if (const std::string problem = xmlShapeProblem(urdf_xml); !problem.empty())
    fail(origin, "not a usable URDF: the text " + problem);
#if NAO_URDF_READER_TINYXML
  const char* reader = "the URDF reader";
  std::string reason;
  const std::shared_ptr<urdf::ModelInterface> urdf = parseUrdfTinyXml(urdf_xml, reason);
#else
  const char* reader = "urdfdom";
  std::string reason;
  const std::shared_ptr<urdf::ModelInterface> urdf = parseUrdfUrdfdom(urdf_xml, reason);
#endif
  if (!urdf)
    fail(origin, "not a valid URDF (" + (reason.empty() ? std::string(reader) + " gave no reason" : reason) + ")");
  return armModelFromUrdf(*urdf, origin);
}

ArmModel armModelFromUrdf(const urdf::ModelInterface& urdf_model, const std::string& origin) {
  const urdf::ModelInterface* urdf = &urdf_model;
  ArmModel model;
  std::string parent_link = kTorsoLink;
  if (!urdf->getLink(parent_link)) fail(origin, "has no link named '" + parent_link + "'");

  for (int j = 0; j < kNumJoints; ++j) {
    const std::string name = kJointNames[j];
    const urdf::JointConstSharedPtr joint = urdf->getJoint(name);
    if (!joint) fail(origin, "has no joint named '" + name + "'");
    if (joint->type != urdf::Joint::REVOLUTE)
      fail(origin, "joint '" + name + "' is of type " + typeName(joint->type) + "; expected revolute");
    if (joint->parent_link_name != parent_link)
      fail(origin, "joint '" + name + "' has parent link '" + joint->parent_link_name + "'; expected '" +
                       parent_link + "' (the chain is torso > " + kJointNames[0] + " > ... > " + kJointNames[4] + ")");
    if (!joint->limits) fail(origin, "joint '" + name + "' has no <limit>");
    const urdf::JointLimits& lim = *joint->limits;
    if (!(lim.lower < lim.upper))
      fail(origin, "joint '" + name + "' has limit lower=" + num(lim.lower) + " upper=" + num(lim.upper) +
                       " (missing or empty range)");
    if (!(std::abs(lim.lower) <= kMaxLimit_rad) || !(std::abs(lim.upper) <= kMaxLimit_rad))
      fail(origin, "joint '" + name + "' has limit lower=" + num(lim.lower) + " upper=" + num(lim.upper) +
                       " (a revolute joint's limits lie within one turn, |q| <= 2 pi)");
    if (!(lim.velocity > 0.0) || !(lim.velocity <= kMaxVelocity_rads))
      fail(origin, "joint '" + name + "' has velocity limit " + num(lim.velocity) + "; expected > 0 and <= " +
                       num(kMaxVelocity_rads) + " rad/s");
    if (!(lim.effort > 0.0) || !(lim.effort <= kMaxEffort_Nm))
      fail(origin, "joint '" + name + "' has effort limit " + num(lim.effort) + "; expected > 0 and <= " +
                       num(kMaxEffort_Nm) + " N m");
    const Eigen::Vector3d axis = toEigen(joint->axis);
    if (!(axis.norm() > 0.5) || !axis.allFinite())
      fail(origin, "joint '" + name + "' has a zero or non-finite rotation axis");
    checkPose(joint->parent_to_joint_origin_transform, origin, "joint '" + name + "'");

    model.p_PJ[j] = toEigen(joint->parent_to_joint_origin_transform.position);
    model.R_PJ[j] = toEigen(joint->parent_to_joint_origin_transform.rotation);
    model.axis_J[j] = axis.normalized();
    model.q_min[j] = lim.lower;
    model.q_max[j] = lim.upper;
    model.v_max[j] = lim.velocity;
    model.tau_max[j] = lim.effort;

    const urdf::LinkConstSharedPtr child = urdf->getLink(joint->child_link_name);
    if (!child) fail(origin, "joint '" + name + "' moves link '" + joint->child_link_name + "', which does not exist");
    model.link[j] = readInertial(*child, origin);
    parent_link = child->name;
  }

  // The hand point: r_hand hangs off the wrist link by one fixed joint.
  const urdf::LinkConstSharedPtr hand = urdf->getLink(kHandLink);
  if (!hand) fail(origin, std::string("has no link named '") + kHandLink + "'");
  const urdf::JointConstSharedPtr hand_joint = hand->parent_joint;
  if (!hand_joint || hand_joint->parent_link_name != parent_link)
    fail(origin, std::string("link '") + kHandLink + "' must be attached to '" + parent_link + "'");
  if (hand_joint->type != urdf::Joint::FIXED)
    fail(origin, "joint '" + hand_joint->name + "' to '" + kHandLink + "' is of type " + typeName(hand_joint->type) +
                     "; expected fixed");
  checkPose(hand_joint->parent_to_joint_origin_transform, origin, "joint '" + hand_joint->name + "'");
  model.p_WH = toEigen(hand_joint->parent_to_joint_origin_transform.position);
  model.R_WH = toEigen(hand_joint->parent_to_joint_origin_transform.rotation);
  return model;
}

}  // namespace nao
