// Camera calibration files (docs/formats.md): our JSON (read by the runtime's reader,
// nao/calibration_json.hpp) and the OpenCV/Anipose-style TOML (toml++, toolchain only).
//
// Both hold, per camera, `size` [w, h] (px), `matrix` K (3x3, px), `distortions` (OpenCV
// k1 k2 p1 p2 [k3]), `rotation` (Rodrigues vector, or a 3x3 rotation matrix) and
// `translation` (m), together world -> camera: p_C = R(rotation) p_W + translation.
// JSON: {"cameras": [{...}, ...]}. TOML: one table per camera, named cam_<N> or holding a
// `matrix` key, in file order; other tables (e.g. [metadata]) are skipped. Every camera of
// either format goes through the runtime's cameraFromJson, so both obey the same checks.
#pragma once

#include "nao/calibration_json.hpp"
#include "nao/tools/camera.hpp"

#include <Eigen/Core>

#include <string>

namespace nao::tools {

using nao::rodriguesFromRotation;
using nao::rotationFromRodrigues;

/// Parses our calibration JSON (nao::parseCameraSetJson); `source` names it in messages.
/// Throws UserError (one line naming the source, the camera and the field) for text that does
/// not parse, no cameras, a missing field, a wrong shape, a non-finite value, a non-positive
/// focal length or image size, a K whose last row is not 0 0 1, or a rotation matrix that is
/// not a rotation.
CameraSet parseCalibrationJson(const std::string& text, const std::string& source);

/// Parses an OpenCV/Anipose-style calibration TOML (same checks as parseCalibrationJson).
CameraSet parseCalibrationToml(const std::string& text, const std::string& source);

/// Reads a calibration file, JSON or TOML by its extension (.json / .toml).
CameraSet readCalibration(const std::string& path);

/// Our calibration JSON text for `cameras` (rotation written as a Rodrigues vector).
std::string formatCalibrationJson(const CameraSet& cameras);

}  // namespace nao::tools
