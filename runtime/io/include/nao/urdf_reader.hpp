// URDF text -> urdfdom's model types (urdf::ModelInterface and friends, header-only from
// urdfdom_headers), by one of two readers; parseArmModel (arm_model.hpp) uses the one the build
// chose (NAO_URDF_READER):
//   urdfdom  urdfdom's own parser (liburdfdom_model): the default, a shared library in Debian;
//   tinyxml  urdf_tinyxml.cpp: TinyXML (static archive in Debian) + urdfdom_headers' inline value
//            parsers, for the statically linked robot build (preset nao, docs/embedded.md).
// Both give the same ArmModel bit for bit on a valid URDF (tests/test_urdf_reader.cpp).
// Configure time only: allocate, never called from the loop.
#pragma once

#include "nao/arm_model_io.hpp"

#include <urdf_model/model.h>

#include <memory>
#include <string>

namespace nao {

/// urdfdom's parser; its console_bridge error lines are collected into `reason`. Returns nullptr
/// (and a non-empty reason, when urdfdom gave one) for a rejected text. Not in NAO_URDF_READER=tinyxml builds.
std::shared_ptr<urdf::ModelInterface> parseUrdfUrdfdom(const std::string& urdf_xml, std::string& reason);

/// The TinyXML reader (urdf_tinyxml.cpp says what it reads). Returns nullptr and a one-line
/// `reason` for a rejected text.
std::shared_ptr<urdf::ModelInterface> parseUrdfTinyXml(const std::string& urdf_xml, std::string& reason);

/// The arm model of a parsed URDF (the checks of loadArmModel). Throws ArmModelError naming
/// `origin` and the problem.
ArmModel armModelFromUrdf(const urdf::ModelInterface& urdf, const std::string& origin);

}  // namespace nao
