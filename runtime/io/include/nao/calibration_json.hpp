// Camera calibration in our JSON (docs/formats.md "Calibration, our JSON"), read by nao_rt
// (--calibration) and the toolchain alike. The toolchain also reads OpenCV/Anipose-style TOML
// (toolchain/src/data/calibration.cpp, toml++): it converts each TOML camera table to JSON and
// checks it with cameraFromJson, so both formats obey the same rules.
//
// Per camera: `size` [w, h] (px), `matrix` K (3x3, px), `distortions` (OpenCV k1 k2 p1 p2 [k3]),
// `rotation` (Rodrigues vector, or a 3x3 rotation matrix) and `translation` (m), together
// world -> camera: p_C = R(rotation) p_W + translation. JSON: {"cameras": [{...}, ...]}.
// Configure time only: these allocate and throw InputError.
#pragma once

#include "nao/camera.hpp"

#include <nlohmann/json_fwd.hpp>

#include <string>

namespace nao {

/// Parses our calibration JSON; `source` names it in messages. Throws InputError (one line
/// naming the source, the camera and the field) for text that does not parse, no cameras, a
/// missing field, a wrong shape, a non-finite value, implausible intrinsics (focal length
/// outside 1 px .. 1e6 px, principal point beyond ten image sizes), a K whose last row is not
/// 0 0 1, a rotation that is not one, a camera farther than 1 km, or two cameras less than
/// 1 mm apart.
CameraSet parseCameraSetJson(const std::string& text, const std::string& source);

/// Reads and parses a calibration JSON file (parseCameraSetJson). Throws InputError.
CameraSet readCameraSetJson(const std::string& path);

/// Our calibration JSON text for `cameras` (rotation written as a Rodrigues vector).
std::string formatCameraSetJson(const CameraSet& cameras);

/// One camera from a JSON object, with every check of parseCameraSetJson; `where` prefixes
/// the messages, `default_name` names a camera without a `name` field. Throws InputError.
Camera cameraFromJson(const nlohmann::json& cam_json, const std::string& where, const std::string& default_name);

/// Throws InputError naming `source` and both cameras when two camera centres are less than
/// 1 mm apart (no baseline: nothing would triangulate).
void checkDistinctCameras(const CameraSet& cameras, const std::string& source);

}  // namespace nao
