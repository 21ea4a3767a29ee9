// The URDF reader of static builds (preset nao, NAO_URDF_READER=tinyxml): Debian ships
// urdfdom's parser only as a shared library, and a binary for the robot's own OS is linked
// statically (docs/embedded.md). The XML is read with TinyXML (urdfdom's own XML library,
// whose static archive Debian ships), every value with urdfdom_headers' inline parsers
// (urdf::Vector3::init, urdf::Rotation::init, urdf::strToDouble) and the tree is linked with
// urdf::ModelInterface::initTree/initRoot: the same numbers as urdfdom, bit for bit
// (tests/test_urdf_reader.cpp compares the two on the project's URDF and on broken ones).
//
// Read: <robot name>, every <link name> with its <inertial> (origin, mass, inertia), every
// <joint name type> with origin, parent, child, axis and limit. Not read (the arm model does
// not use them): visual, collision, material, dynamics, safety, calibration, mimic; so a
// malformed <visual> that urdfdom rejects passes here. Configure time only: allocates, throws.
#include "nao/urdf_reader.hpp"

#include <tinyxml.h>
#include <urdf_exception/exception.h>

#include <map>
#include <set>
#include <string>
#include <vector>

namespace nao {
namespace {

const char* attribute(const TiXmlElement& e, const char* name) { return e.Attribute(name); }

std::string requiredAttribute(const TiXmlElement& e, const char* name, const std::string& where) {
  const char* v = attribute(e, name);
  if (v == nullptr) throw urdf::ParseError(where + " has no '" + name + "' attribute");
  return v;
}

double number(const TiXmlElement& e, const char* name, const std::string& where) {
  const std::string text = requiredAttribute(e, name, where);
  try {
    return urdf::strToDouble(text.c_str());
  } catch (const std::exception&) {
    throw urdf::ParseError(where + ": attribute '" + name + "' is not a number: '" + text + "'");
  }
}

// <origin xyz rpy>, both optional (zero), as urdfdom's parsePose.
urdf::Pose readPose(const TiXmlElement* origin) {
  urdf::Pose pose;
  pose.clear();
  if (origin == nullptr) return pose;
  if (const char* xyz = attribute(*origin, "xyz")) pose.position.init(xyz);
  if (const char* rpy = attribute(*origin, "rpy")) pose.rotation.init(rpy);
  return pose;
}

urdf::InertialSharedPtr readInertial(const TiXmlElement& xml, const std::string& link) {
  auto in = std::make_shared<urdf::Inertial>();
  in->clear();
  const std::string where = "link [" + link + "] <inertial>";
  in->origin = readPose(xml.FirstChildElement("origin"));
  const TiXmlElement* mass = xml.FirstChildElement("mass");
  if (mass == nullptr) throw urdf::ParseError(where + " has no <mass>");
  in->mass = number(*mass, "value", where + " <mass>");
  const TiXmlElement* inertia = xml.FirstChildElement("inertia");
  if (inertia == nullptr) throw urdf::ParseError(where + " has no <inertia>");
  const std::string w = where + " <inertia>";
  in->ixx = number(*inertia, "ixx", w);
  in->ixy = number(*inertia, "ixy", w);
  in->ixz = number(*inertia, "ixz", w);
  in->iyy = number(*inertia, "iyy", w);
  in->iyz = number(*inertia, "iyz", w);
  in->izz = number(*inertia, "izz", w);
  return in;
}

decltype(urdf::Joint::type) jointType(const std::string& type, const std::string& where) {
  if (type == "revolute") return urdf::Joint::REVOLUTE;
  if (type == "continuous") return urdf::Joint::CONTINUOUS;
  if (type == "prismatic") return urdf::Joint::PRISMATIC;
  if (type == "floating") return urdf::Joint::FLOATING;
  if (type == "planar") return urdf::Joint::PLANAR;
  if (type == "fixed") return urdf::Joint::FIXED;
  throw urdf::ParseError(where + " has unknown type '" + type + "'");
}

urdf::JointSharedPtr readJoint(const TiXmlElement& xml) {
  auto joint = std::make_shared<urdf::Joint>();
  joint->clear();
  joint->name = requiredAttribute(xml, "name", "a <joint>");
  const std::string where = "joint [" + joint->name + "]";
  joint->type = jointType(requiredAttribute(xml, "type", where), where);
  joint->parent_to_joint_origin_transform = readPose(xml.FirstChildElement("origin"));
  if (const TiXmlElement* parent = xml.FirstChildElement("parent"))
    joint->parent_link_name = requiredAttribute(*parent, "link", where + " <parent>");
  if (const TiXmlElement* child = xml.FirstChildElement("child"))
    joint->child_link_name = requiredAttribute(*child, "link", where + " <child>");
  // As urdfdom: no <axis> is the x axis; an <axis> without xyz leaves it zero (rejected by the
  // arm model).
  if (joint->type != urdf::Joint::FIXED && joint->type != urdf::Joint::FLOATING) {
    if (const TiXmlElement* axis = xml.FirstChildElement("axis")) {
      if (const char* xyz = attribute(*axis, "xyz")) joint->axis.init(xyz);
    } else {
      joint->axis = urdf::Vector3(1.0, 0.0, 0.0);
    }
  }
  const TiXmlElement* limit = xml.FirstChildElement("limit");
  if (limit != nullptr) {
    auto lim = std::make_shared<urdf::JointLimits>();
    lim->clear();
    const std::string w = where + " <limit>";
    // lower and upper default to 0 (urdfdom); effort and velocity are required.
    if (attribute(*limit, "lower") != nullptr) lim->lower = number(*limit, "lower", w);
    if (attribute(*limit, "upper") != nullptr) lim->upper = number(*limit, "upper", w);
    lim->effort = number(*limit, "effort", w);
    lim->velocity = number(*limit, "velocity", w);
    joint->limits = lim;
  } else if (joint->type == urdf::Joint::REVOLUTE || joint->type == urdf::Joint::PRISMATIC) {
    throw urdf::ParseError(where + " is of a type that needs a <limit>");
  }
  return joint;
}

}  // namespace

std::shared_ptr<urdf::ModelInterface> parseUrdfTinyXml(const std::string& urdf_xml, std::string& reason) {
  reason.clear();
  TiXmlDocument doc;
  doc.Parse(urdf_xml.c_str());
  if (doc.Error()) {
    reason = std::string("XML error: ") + doc.ErrorDesc() + " at line " + std::to_string(doc.ErrorRow());
    return nullptr;
  }
  const TiXmlElement* robot = doc.FirstChildElement("robot");
  if (robot == nullptr) {
    reason = "no <robot> element";
    return nullptr;
  }
  auto model = std::make_shared<urdf::ModelInterface>();
  try {
    model->clear();
    model->name_ = requiredAttribute(*robot, "name", "<robot>");
    for (const TiXmlElement* e = robot->FirstChildElement("link"); e != nullptr; e = e->NextSiblingElement("link")) {
      auto link = std::make_shared<urdf::Link>();
      link->clear();
      link->name = requiredAttribute(*e, "name", "a <link>");
      if (const TiXmlElement* inertial = e->FirstChildElement("inertial")) link->inertial = readInertial(*inertial, link->name);
      if (!model->links_.emplace(link->name, link).second)
        throw urdf::ParseError("link [" + link->name + "] is not unique");
    }
    if (model->links_.empty()) throw urdf::ParseError("no <link> element");
    for (const TiXmlElement* e = robot->FirstChildElement("joint"); e != nullptr; e = e->NextSiblingElement("joint")) {
      urdf::JointSharedPtr joint = readJoint(*e);
      if (!model->joints_.emplace(joint->name, joint).second)
        throw urdf::ParseError("joint [" + joint->name + "] is not unique");
    }
    std::map<std::string, std::string> parent_link_tree;
    model->initTree(parent_link_tree);
    model->initRoot(parent_link_tree);
    // initTree links any graph of joints, loops included (A→B→A beside a root C passes initRoot):
    // a tree reaches every link from the root exactly once. Anything else is refused here, and
    // the catch below cuts the cycle's shared pointers (found by fuzz_urdf_tinyxml: a leak).
    std::vector<urdf::LinkSharedPtr> pending{model->root_link_};
    std::set<const urdf::Link*> seen;
    while (!pending.empty()) {
      const urdf::LinkSharedPtr link = pending.back();
      pending.pop_back();
      if (!seen.insert(link.get()).second) throw urdf::ParseError("link [" + link->name + "] is reached twice: not a tree");
      for (const urdf::LinkSharedPtr& child : link->child_links) pending.push_back(child);
    }
    if (seen.size() != model->links_.size())
      throw urdf::ParseError("the joints do not form one tree from the root link [" + model->root_link_->name +
                             "]: a loop of links without a path from it");
    return model;
  } catch (const std::exception& e) {
    reason = e.what();
    // A rejected tree may hold a cycle of shared pointers (a link that is its own child): cut the
    // links' ownership of their children so everything is freed.
    for (auto& entry : model->links_) {
      entry.second->child_links.clear();
      entry.second->child_joints.clear();
      entry.second->parent_joint.reset();
    }
    return nullptr;
  }
}

}  // namespace nao
