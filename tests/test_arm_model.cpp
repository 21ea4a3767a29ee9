// ArmModel: the URDF is read into the numbers of docs/nao_v6_facts.md, and every malformed
// file is refused with a message that names the problem.
#include "nao/arm_model.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <string>

using namespace nao;
using nao::test::kUrdfPath;

namespace {

// The project's URDF text with one substring replaced; fails the test if it is not there.
std::string urdfWith(const std::string& from, const std::string& to) {
  std::string text = nao::test::readFile(kUrdfPath);
  const auto at = text.find(from);
  REQUIRE_MESSAGE(at != std::string::npos, "the URDF no longer contains '" << from << "'");
  text.replace(at, from.size(), to);
  return text;
}

// Loads `text` through a file (the path users take) and returns the error message.
std::string loadError(const std::string& name, const std::string& text) {
  const std::string path = nao::test::writeTempFile(name, text);
  try {
    loadArmModel(path);
  } catch (const ArmModelError& e) {
    return e.what();
  }
  FAIL("loading " << name << " should have thrown ArmModelError");
  return {};
}

}  // namespace

TEST_CASE("the URDF carries the NAO V6 joint limits, velocities and efforts from the reference facts") {
  const ArmModel m = loadArmModel(kUrdfPath);
  const double lo[] = {-2.08567, -1.32645, -2.08567, 0.0349066, -1.82387};
  const double hi[] = {2.08567, 0.314159, 2.08567, 1.54462, 1.82387};
  const double vel[] = {8.26797, 7.19407, 8.26797, 7.19407, 24.6229};
  const double eff[] = {1.329, 1.783, 1.547, 1.532, 0.4075};
  for (int j = 0; j < kNumJoints; ++j) {
    const std::string joint = kJointNames[j];
    CAPTURE(joint);
    CHECK(m.q_min[j] == lo[j]);
    CHECK(m.q_max[j] == hi[j]);
    CHECK(m.v_max[j] == vel[j]);
    CHECK(m.tau_max[j] == eff[j]);
  }
  CHECK(m.p_WH.isApprox(Eigen::Vector3d(0.05775, 0.0, -0.01231)));
  // Arm mass shoulder..hand, as the facts sum it.
  double mass = 0.0;
  for (const LinkInertial& L : m.link) mass += L.mass;
  CHECK(mass == doctest::Approx(0.57858).epsilon(1e-9));
}

TEST_CASE("robot scale d_r is the sum of upper arm, forearm and hand lengths") {
  const ArmModel m = loadArmModel(kUrdfPath);
  // UpperArmLength 105 mm with ElbowOffsetY 15 mm, LowerArmLength 55.95 mm, hand (57.75, -12.31) mm.
  const double expected = std::hypot(0.105, 0.015) + 0.05595 + std::hypot(0.05775, 0.01231);
  CHECK(robotScale(m) == doctest::Approx(expected).epsilon(1e-12));
  CHECK(robotScale(m) == doctest::Approx(0.221063).epsilon(1e-5));
}

TEST_CASE("clampToLimits keeps every joint inside its URDF range") {
  const ArmModel m = loadArmModel(kUrdfPath);
  JointVector q;
  q << 5.0, -5.0, 0.5, 0.0, 1.0;
  const JointVector c = clampToLimits(m, q);
  CHECK(c[0] == m.q_max[0]);
  CHECK(c[1] == m.q_min[1]);
  CHECK(c[2] == 0.5);
  CHECK(c[3] == m.q_min[3]);
  CHECK(c[4] == 1.0);
}

TEST_CASE("a missing URDF file is refused with a message naming the file") {
  const std::string missing = "/nonexistent/dir/nao_missing.urdf";
  try {
    loadArmModel(missing);
    FAIL("expected ArmModelError");
  } catch (const ArmModelError& e) {
    const std::string msg = e.what();
    CHECK_MESSAGE(msg.find(missing) != std::string::npos, msg);
    CHECK_MESSAGE(msg.find("cannot open") != std::string::npos, msg);
  }
}

TEST_CASE("a URDF that is not XML is refused with urdfdom's reason") {
  const std::string msg = loadError("not_xml.urdf", "<robot name='x'><link name='torso'>");
  CHECK_MESSAGE(msg.find("not a valid URDF") != std::string::npos, msg);
}

TEST_CASE("a URDF missing an arm joint is refused naming that joint") {
  const std::string msg = loadError("missing_joint.urdf", urdfWith("name=\"RElbowYaw\"", "name=\"RElbowYawX\""));
  CHECK_MESSAGE(msg.find("no joint named 'RElbowYaw'") != std::string::npos, msg);
}

TEST_CASE("a URDF with an arm joint of the wrong type is refused naming the joint and the type") {
  const std::string msg =
      loadError("wrong_type.urdf", urdfWith("<joint name=\"RElbowRoll\" type=\"revolute\">",
                                            "<joint name=\"RElbowRoll\" type=\"continuous\">"));
  CHECK_MESSAGE(msg.find("'RElbowRoll'") != std::string::npos, msg);
  CHECK_MESSAGE(msg.find("continuous; expected revolute") != std::string::npos, msg);

  const std::string fixed = loadError(
      "hand_not_fixed.urdf", urdfWith("<joint name=\"RHandPoint\" type=\"fixed\">",
                                      "<joint name=\"RHandPoint\" type=\"revolute\"><axis xyz=\"1 0 0\"/>"
                                      "<limit lower=\"0\" upper=\"1\" velocity=\"1\" effort=\"1\"/>"));
  CHECK_MESSAGE(fixed.find("RHandPoint") != std::string::npos, fixed);
  CHECK_MESSAGE(fixed.find("expected fixed") != std::string::npos, fixed);
}

TEST_CASE("a URDF whose arm joint lacks its <limit> is refused naming the joint and the limit") {
  const std::string line =
      "<limit lower=\"0.0349066\" upper=\"1.54462\" velocity=\"7.19407\" effort=\"1.532\"/>";
  const std::string msg = loadError("missing_limit.urdf", urdfWith(line, ""));
  CHECK_MESSAGE(msg.find("RElbowRoll") != std::string::npos, msg);
  CHECK_MESSAGE(msg.find("limit") != std::string::npos, msg);
}

TEST_CASE("a URDF whose limit has no range or no velocity is refused naming the joint") {
  const std::string no_range = loadError(
      "empty_range.urdf", urdfWith("lower=\"-1.82387\" upper=\"1.82387\"", "velocity_unused=\"0\""));
  CHECK_MESSAGE(no_range.find("RWristYaw") != std::string::npos, no_range);
  CHECK_MESSAGE(no_range.find("empty range") != std::string::npos, no_range);

  const std::string no_vel =
      loadError("zero_velocity.urdf", urdfWith("velocity=\"24.6229\"", "velocity=\"0\""));
  CHECK_MESSAGE(no_vel.find("RWristYaw") != std::string::npos, no_vel);
  CHECK_MESSAGE(no_vel.find("velocity") != std::string::npos, no_vel);
}

TEST_CASE("a URDF whose chain is wired differently or lacks the hand link is refused") {
  const std::string wired = loadError(
      "miswired.urdf", urdfWith("<parent link=\"RBicep\"/>\n    <child link=\"RElbow\"/>",
                                "<parent link=\"RShoulder\"/>\n    <child link=\"RElbow\"/>"));
  CHECK_MESSAGE(wired.find("RElbowYaw") != std::string::npos, wired);
  CHECK_MESSAGE(wired.find("expected 'RBicep'") != std::string::npos, wired);

  const std::string no_hand =
      loadError("no_hand.urdf", urdfWith("<link name=\"r_hand\"/>", "<link name=\"r_hand_renamed\"/>"));
  CHECK_MESSAGE(no_hand.find("r_hand") != std::string::npos, no_hand);
}

TEST_CASE("URDF text that could crash or mislead the parser is refused before it") {
  // 60000 nested elements overflowed the stack inside TinyXML.
  const std::string deep = loadError("deep.urdf", "<?xml version=\"1.0\"?>\n<robot name=\"x\">" +
                                                       [] {
                                                         std::string s;
                                                         for (int i = 0; i < 60000; ++i) s += "<a>";
                                                         for (int i = 0; i < 60000; ++i) s += "</a>";
                                                         return s;
                                                       }() +
                                                       "</robot>");
  CHECK_MESSAGE(deep.find("deep.urdf: not a usable URDF: the text nests deeper than 64 levels") != std::string::npos, deep);
  // These 36 bytes end in a UTF-8 lead byte: TinyXML read past the buffer.
  const std::string cut = loadError("utf8.urdf", std::string("<?xml version=\"1.0\"?>\n<robot name=\"\xF2"));
  CHECK_MESSAGE(cut.find("utf8.urdf: not a usable URDF: the text is not valid UTF-8") != std::string::npos, cut);
  const std::string nul = loadError("nul.urdf", std::string("<robot name=\"x\">\0</robot>", 25));
  CHECK_MESSAGE(nul.find("NUL byte") != std::string::npos, nul);
  // Comments, CDATA and self-closing tags do not count as nesting: the project's URDF loads.
  CHECK_NOTHROW(nao::parseArmModel("<!-- <a><a><a> -->" + nao::test::readFile(kUrdfPath), "commented.urdf"));
}

TEST_CASE("a URDF whose numbers are finite but absurd is refused naming the joint") {
  const std::string far = loadError("far.urdf", urdfWith("<origin xyz=\"0.105 -0.015 0\"", "<origin xyz=\"1e308 -0.015 0\""));
  CHECK_MESSAGE(far.find("joint 'RElbowYaw' origin xyz=\"1e+308 -0.015 0\" is not finite or not within 10 m") !=
                    std::string::npos,
                far);
  const std::string hand = loadError("far_hand.urdf", urdfWith("<origin xyz=\"0.05775 0 -0.01231\"", "<origin xyz=\"0.05775 0 -12\""));
  CHECK_MESSAGE(hand.find("RHandPoint") != std::string::npos, hand);
  const std::string limit = loadError("turns.urdf", urdfWith("lower=\"-1.82387\"", "lower=\"-100\""));
  CHECK_MESSAGE(limit.find("joint 'RWristYaw' has limit lower=-100") != std::string::npos, limit);
  const std::string speed = loadError("fast.urdf", urdfWith("velocity=\"24.6229\"", "velocity=\"1e300\""));
  CHECK_MESSAGE(speed.find("joint 'RWristYaw' has velocity limit 1e+300") != std::string::npos, speed);
}
