// The two URDF readers (runtime/io/include/nao/urdf_reader.hpp): urdfdom's parser, which the native
// build uses, and the TinyXML reader of the static robot build (preset nao). The robot must get
// the arm the tests and the simulator were checked with, so the two must agree bit for bit.
#include "nao/urdf_reader.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

namespace {

std::string readText(const std::string& path) {
  std::ifstream in(path);
  REQUIRE_MESSAGE(in, "cannot open " << path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

template <class T>
bool sameBits(const T& a, const T& b) {
  return std::memcmp(a.data(), b.data(), sizeof(typename T::Scalar) * static_cast<std::size_t>(a.size())) == 0;
}

nao::ArmModel armFrom(const std::shared_ptr<urdf::ModelInterface>& urdf, const std::string& reason) {
  REQUIRE_MESSAGE(urdf != nullptr, "the reader rejected the URDF: " << reason);
  return nao::armModelFromUrdf(*urdf, "test");
}

// A small valid URDF of the arm's shape, edited by the rejection cases.
std::string urdfWith(const std::string& joint0_extra, const std::string& joint0_type = "revolute",
                     const std::string& joint0_child = "l1") {
  return "<robot name='r'><link name='torso'/>"
         "<link name='l1'><inertial><mass value='1'/><inertia ixx='1' ixy='0' ixz='0' iyy='1' iyz='0' izz='1'/></inertial></link>"
         "<joint name='RShoulderPitch' type='" + joint0_type + "'><parent link='torso'/><child link='" + joint0_child + "'/>" +
         joint0_extra + "</joint></robot>";
}

}  // namespace

TEST_CASE("the TinyXML reader gives urdfdom's arm model bit for bit on the project's URDF") {
  const std::string xml = readText(NAO_DEFAULT_URDF);
  std::string reason_dom, reason_tiny;
  const nao::ArmModel a = armFrom(nao::parseUrdfUrdfdom(xml, reason_dom), reason_dom);
  const nao::ArmModel b = armFrom(nao::parseUrdfTinyXml(xml, reason_tiny), reason_tiny);
  for (int j = 0; j < nao::kNumJoints; ++j) {
    CAPTURE(nao::kJointNames[j]);
    const std::size_t k = static_cast<std::size_t>(j);
    CHECK(sameBits(a.p_PJ[k], b.p_PJ[k]));
    CHECK(sameBits(a.R_PJ[k], b.R_PJ[k]));
    CHECK(sameBits(a.axis_J[k], b.axis_J[k]));
    CHECK(std::memcmp(&a.link[k].mass, &b.link[k].mass, sizeof(double)) == 0);
    CHECK(sameBits(a.link[k].p_LC, b.link[k].p_LC));
    CHECK(sameBits(a.link[k].I_C, b.link[k].I_C));
  }
  CHECK(sameBits(a.q_min, b.q_min));
  CHECK(sameBits(a.q_max, b.q_max));
  CHECK(sameBits(a.v_max, b.v_max));
  CHECK(sameBits(a.tau_max, b.tau_max));
  CHECK(sameBits(a.p_WH, b.p_WH));
  CHECK(sameBits(a.R_WH, b.R_WH));
  // Not a vacuous comparison: the model has non-trivial numbers.
  CHECK(a.q_max[0] > 2.0);
  CHECK(a.link[4].mass > 0.0);
}

TEST_CASE("the TinyXML reader rejects what urdfdom rejects, with a reason") {
  const std::string limit = "<limit lower='-1' upper='1' effort='1' velocity='1'/>";
  struct Case {
    const char* what;
    std::string xml;
  };
  const Case cases[] = {
      {"not XML", "<robot name='r'><link name='torso'>"},
      {"no <robot>", "<model name='r'/>"},
      {"a revolute joint without <limit>", urdfWith("")},
      {"a <limit> without velocity", urdfWith("<limit lower='-1' upper='1' effort='1'/>")},
      {"an unknown joint type", urdfWith(limit, "hinge")},
      {"a joint whose child link does not exist", urdfWith(limit, "revolute", "nowhere")},
      {"a non-numeric origin", urdfWith(limit + "<origin xyz='0 0 x'/>")},
      {"an origin with two numbers", urdfWith(limit + "<origin xyz='0 0'/>")},
  };
  // The valid base passes both (so each rejection is the edit's doing).
  std::string reason;
  REQUIRE(nao::parseUrdfUrdfdom(urdfWith(limit), reason) != nullptr);
  REQUIRE(nao::parseUrdfTinyXml(urdfWith(limit), reason) != nullptr);
  for (const Case& c : cases) {
    CAPTURE(c.what);
    std::string reason_dom, reason_tiny;
    CHECK(nao::parseUrdfUrdfdom(c.xml, reason_dom) == nullptr);
    CHECK(nao::parseUrdfTinyXml(c.xml, reason_tiny) == nullptr);
    CHECK_MESSAGE(!reason_tiny.empty(), "the TinyXML reader gave no reason for " << c.what);
  }
}

TEST_CASE("the TinyXML reader gives urdfdom's numbers bit for bit for a rotated origin and decimal text") {
  // The project's URDF has rpy="0 0 0" everywhere: this case exercises the rotation path.
  const std::string xml =
      urdfWith("<limit lower='-2.0857' upper='0.3142' effort='1.329' velocity='8.26797'/>"
               "<axis xyz='0 0.6 0.8'/><origin xyz='0.1 -0.098 1e-1' rpy='0.3 -1.2 2.5'/>");
  std::string reason_dom, reason_tiny;
  const auto a = nao::parseUrdfUrdfdom(xml, reason_dom);
  const auto b = nao::parseUrdfTinyXml(xml, reason_tiny);
  REQUIRE_MESSAGE(a != nullptr, reason_dom);
  REQUIRE_MESSAGE(b != nullptr, reason_tiny);
  const urdf::JointConstSharedPtr ja = a->getJoint("RShoulderPitch"), jb = b->getJoint("RShoulderPitch");
  REQUIRE(ja != nullptr);
  REQUIRE(jb != nullptr);
  const urdf::Pose& pa = ja->parent_to_joint_origin_transform;
  const urdf::Pose& pb = jb->parent_to_joint_origin_transform;
  const double qa[] = {pa.rotation.x, pa.rotation.y, pa.rotation.z, pa.rotation.w, pa.position.x, pa.position.y,
                       pa.position.z, ja->axis.x, ja->axis.y, ja->axis.z, ja->limits->lower, ja->limits->upper,
                       ja->limits->effort, ja->limits->velocity};
  const double qb[] = {pb.rotation.x, pb.rotation.y, pb.rotation.z, pb.rotation.w, pb.position.x, pb.position.y,
                       pb.position.z, jb->axis.x, jb->axis.y, jb->axis.z, jb->limits->lower, jb->limits->upper,
                       jb->limits->effort, jb->limits->velocity};
  for (std::size_t i = 0; i < sizeof qa / sizeof qa[0]; ++i) {
    CAPTURE(i);
    CHECK(std::memcmp(&qa[i], &qb[i], sizeof(double)) == 0);
  }
  CHECK(std::abs(pa.rotation.w) < 0.99);  // a real rotation
  const urdf::LinkConstSharedPtr child = b->getLink("l1");
  REQUIRE(child != nullptr);
  CHECK(child->parent_joint == jb);  // the tree is linked
}

TEST_CASE("the TinyXML reader refuses joints that do not form one tree (a loop beside the root), with a reason") {
  // Found by fuzz_urdf_tinyxml (LeakSanitizer): A→B and B→A beside a root passed initTree and
  // initRoot; the loop's shared pointers were never freed once the arm check refused the model.
  const std::string limit = "<limit lower='-1' upper='1' effort='1' velocity='1'/>";
  const auto joint = [&](const std::string& name, const std::string& parent, const std::string& child) {
    return "<joint name='" + name + "' type='revolute'><parent link='" + parent + "'/><child link='" + child + "'/>" +
           limit + "</joint>";
  };
  const std::string loop = "<robot name='r'><link name='torso'/><link name='a'/><link name='b'/>" +
                           joint("j1", "a", "b") + joint("j2", "b", "a") + "</robot>";
  const std::string self = "<robot name='r'><link name='torso'/><link name='a'/>" + joint("j1", "torso", "a") +
                           joint("j2", "a", "a") + "</robot>";
  const std::string tree = "<robot name='r'><link name='torso'/><link name='a'/><link name='b'/>" +
                           joint("j1", "torso", "a") + joint("j2", "a", "b") + "</robot>";
  std::string reason;
  CHECK(nao::parseUrdfTinyXml(tree, reason) != nullptr);  // the same shape as a tree passes
  CHECK(nao::parseUrdfTinyXml(loop, reason) == nullptr);
  CHECK_MESSAGE(reason.find("tree") != std::string::npos, reason);
  reason.clear();
  CHECK(nao::parseUrdfTinyXml(self, reason) == nullptr);
  CHECK_MESSAGE(!reason.empty(), "no reason for a link that is its own child");
}
