// Reading the arm's URDF into an ArmModel (configure time: file I/O, allocates, throws).
#pragma once

#include "nao/arm_model.hpp"

#include <string>

namespace nao {

/// Reads and validates the URDF at `urdf_path` (configure time, allocates).
/// Throws ArmModelError naming the file and the problem: unreadable file, XML urdfdom
/// rejects, a missing joint or link, a joint of the wrong type or in the wrong place in the
/// chain, a missing or empty limit, a non-positive mass or velocity/effort limit.
ArmModel loadArmModel(const std::string& urdf_path);

/// As loadArmModel, from URDF text; `origin` names the source in error messages.
ArmModel parseArmModel(const std::string& urdf_xml, const std::string& origin);

}  // namespace nao
