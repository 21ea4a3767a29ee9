#include "nao/calibration_json.hpp"

#include "nao/input_error.hpp"
#include "nao/text_guard.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>

namespace nao {
namespace {

using nlohmann::json;

std::string shapeOf(const json& v) {
  if (v.is_array()) return "an array of " + std::to_string(v.size());
  if (v.is_number()) return "a number";
  if (v.is_string()) return "a string";
  if (v.is_object()) return "a table";
  if (v.is_boolean()) return "a boolean";
  return "null";
}

// Reads a flat array of numbers of one of the allowed lengths.
std::vector<double> numbers(const json& cam, const char* field, std::initializer_list<std::size_t> lengths,
                            const std::string& where, const char* meaning) {
  const auto it = cam.find(field);
  if (it == cam.end()) throw InputError(where + ": missing field '" + field + "' (" + meaning + ")");
  const json& v = *it;
  const bool length_ok = v.is_array() && std::find(lengths.begin(), lengths.end(), v.size()) != lengths.end();
  const bool all_numbers = v.is_array() && std::all_of(v.begin(), v.end(), [](const json& e) { return e.is_number(); });
  if (!length_ok || !all_numbers)
    throw InputError(where + ": field '" + field + "' is " + shapeOf(v) + (all_numbers ? "" : " (not all numbers)") +
                     ", expected " + meaning);
  std::vector<double> out;
  for (const json& e : v) {
    out.push_back(e.get<double>());
    if (!std::isfinite(out.back())) throw InputError(where + ": field '" + field + "' holds a non-finite value");
  }
  return out;
}

bool isMatrix3(const json& v) {
  if (!v.is_array() || v.size() != 3) return false;
  for (const json& row : v) {
    if (!row.is_array() || row.size() != 3) return false;
    for (const json& e : row)
      if (!e.is_number()) return false;
  }
  return true;
}

Eigen::Matrix3d matrix3(const json& v, const std::string& where, const char* field) {
  Eigen::Matrix3d M;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      M(r, c) = v[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)].get<double>();
      if (!std::isfinite(M(r, c))) throw InputError(where + ": field '" + field + "' holds a non-finite value");
    }
  return M;
}

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Plausible camera geometry. Real focal lengths are tens to thousands of pixels; a value far
// outside makes every projection degenerate, so triangulation would run and find nothing.
constexpr double kMinFocal_px = 1.0;
constexpr double kMaxFocal_px = 1e6;
// A Rodrigues vector's norm is the rotation angle: writers give it in [0, pi], at most 2 pi.
constexpr double kMaxRotationAngle = 2.0 * 3.14159265358979323846 + 1e-9;
// Cameras watch one person: farther than 1 km from the world origin is a unit or sign slip.
constexpr double kMaxDistance_m = 1000.0;
// Two cameras whose centres are closer than this see no parallax: nothing triangulates.
constexpr double kMinBaseline_m = 1e-3;

// The library's message without its "[json.exception.<kind>.<id>] " prefix.
std::string jsonReason(const std::exception& e) {
  std::string what = e.what();
  const auto bracket = what.find("] ");
  return bracket == std::string::npos ? what : what.substr(bracket + 2);
}

}  // namespace

Eigen::Matrix3d rotationFromRodrigues(const Eigen::Vector3d& r) {
  const double angle = r.norm();
  if (angle < 1e-12) {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    R(0, 1) = -r.z(), R(0, 2) = r.y(), R(1, 0) = r.z(), R(1, 2) = -r.x(), R(2, 0) = -r.y(), R(2, 1) = r.x();
    return R;
  }
  return Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
}

Eigen::Vector3d rodriguesFromRotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

Camera cameraFromJson(const json& cam_json, const std::string& where, const std::string& default_name) {
  if (!cam_json.is_object()) throw InputError(where + ": a camera must be an object/table, got " + shapeOf(cam_json));
  Camera cam;
  const auto name = cam_json.find("name");
  cam.name = (name != cam_json.end() && name->is_string()) ? name->get<std::string>() : default_name;

  const std::vector<double> size = numbers(cam_json, "size", {2}, where, "[width, height] in pixels");
  if (size[0] < 1.0 || size[1] < 1.0 || size[0] != std::floor(size[0]) || size[1] != std::floor(size[1]) ||
      size[0] > 1e6 || size[1] > 1e6)
    throw InputError(where + ": 'size' must be two positive integers [width, height], got [" + num(size[0]) + ", " +
                     num(size[1]) + "]");
  cam.width = static_cast<int>(size[0]);
  cam.height = static_cast<int>(size[1]);

  const auto matrix = cam_json.find("matrix");
  if (matrix == cam_json.end()) throw InputError(where + ": missing field 'matrix' (3x3 intrinsics K, px)");
  if (!isMatrix3(*matrix))
    throw InputError(where + ": field 'matrix' is " + shapeOf(*matrix) + ", expected a 3x3 array of numbers (K, px)");
  cam.K = matrix3(*matrix, where, "matrix");
  if (!(cam.K(0, 0) > 0.0) || !(cam.K(1, 1) > 0.0))
    throw InputError(where + ": focal lengths must be positive, got fx=" + num(cam.K(0, 0)) + ", fy=" + num(cam.K(1, 1)));
  if (!(cam.K(0, 0) >= kMinFocal_px && cam.K(0, 0) <= kMaxFocal_px && cam.K(1, 1) >= kMinFocal_px &&
        cam.K(1, 1) <= kMaxFocal_px))
    throw InputError(where + ": focal lengths fx=" + num(cam.K(0, 0)) + ", fy=" + num(cam.K(1, 1)) +
                     " px are not plausible (expected " + num(kMinFocal_px) + " to " + num(kMaxFocal_px) + " px)");
  if (std::abs(cam.K(0, 2)) > 10.0 * cam.width || std::abs(cam.K(1, 2)) > 10.0 * cam.height ||
      std::abs(cam.K(0, 1)) > kMaxFocal_px)
    throw InputError(where + ": principal point (" + num(cam.K(0, 2)) + ", " + num(cam.K(1, 2)) + ") or skew " +
                     num(cam.K(0, 1)) + " px is not plausible for a " + std::to_string(cam.width) + "x" +
                     std::to_string(cam.height) + " image");
  if (cam.K(1, 0) != 0.0 || cam.K(2, 0) != 0.0 || cam.K(2, 1) != 0.0 || cam.K(2, 2) != 1.0)
    throw InputError(where + ": 'matrix' must have the form [[fx, s, cx], [0, fy, cy], [0, 0, 1]]");

  const std::vector<double> dist =
      numbers(cam_json, "distortions", {4, 5}, where, "OpenCV distortion [k1, k2, p1, p2] or [k1, k2, p1, p2, k3]");
  for (std::size_t i = 0; i < dist.size(); ++i) cam.dist[static_cast<Eigen::Index>(i)] = dist[i];

  const auto rotation = cam_json.find("rotation");
  if (rotation == cam_json.end()) throw InputError(where + ": missing field 'rotation' (Rodrigues vector, world -> camera)");
  if (isMatrix3(*rotation)) {
    const Eigen::Matrix3d R = matrix3(*rotation, where, "rotation");
    const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
    if (orthogonality > 1e-6 || R.determinant() < 0.0)
      throw InputError(where + ": 'rotation' matrix is not a rotation (|R^T R - I| = " + num(orthogonality) +
                       ", det = " + num(R.determinant()) + ")");
    cam.R_CW = R;
  } else {
    const std::vector<double> r =
        numbers(cam_json, "rotation", {3}, where, "a Rodrigues vector [rx, ry, rz] or a 3x3 rotation matrix");
    const Eigen::Vector3d rv(r[0], r[1], r[2]);
    // The norm of [1e200, 0, 0] overflows to inf and the matrix would be all NaN.
    if (!(rv.norm() <= kMaxRotationAngle))
      throw InputError(where + ": 'rotation' [" + num(r[0]) + ", " + num(r[1]) + ", " + num(r[2]) +
                       "] is not a rotation: a Rodrigues vector's norm is the angle, at most 2 pi");
    cam.R_CW = rotationFromRodrigues(rv);
  }
  const std::vector<double> t = numbers(cam_json, "translation", {3}, where, "[tx, ty, tz] in metres, world -> camera");
  cam.p_CW = Eigen::Vector3d(t[0], t[1], t[2]);
  if (!(cam.p_CW.norm() <= kMaxDistance_m))
    throw InputError(where + ": 'translation' [" + num(t[0]) + ", " + num(t[1]) + ", " + num(t[2]) +
                     "] puts the camera more than " + num(kMaxDistance_m) + " m away (metres expected)");
  return cam;
}

// Cameras at the same place (a copied block) give no baseline: every point would come out
// invalid, so the file is refused here, naming both.
void checkDistinctCameras(const CameraSet& cams, const std::string& source) {
  for (std::size_t a = 0; a < cams.size(); ++a)
    for (std::size_t b = a + 1; b < cams.size(); ++b) {
      const Eigen::Vector3d c_a = -cams[a].R_CW.transpose() * cams[a].p_CW;
      const Eigen::Vector3d c_b = -cams[b].R_CW.transpose() * cams[b].p_CW;
      if ((c_a - c_b).norm() < kMinBaseline_m)
        throw InputError(source + ": cameras '" + cams[a].name + "' and '" + cams[b].name +
                         "' sit at the same place (centres less than 1 mm apart): triangulation needs a baseline");
    }
}

CameraSet parseCameraSetJson(const std::string& text, const std::string& source) {
  if (const std::string problem = jsonShapeProblem(text); !problem.empty())
    throw InputError(source + ": not a usable calibration file: the JSON text " + problem);
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number like 1e400
    throw InputError(source + ": calibration JSON does not parse: " + jsonReason(e));
  }
  if (!doc.is_object() || !doc.contains("cameras"))
    throw InputError(source + ": no 'cameras' array (expected {\"cameras\": [{...}, ...]})");
  const json& cams = doc["cameras"];
  if (!cams.is_array()) throw InputError(source + ": 'cameras' is " + shapeOf(cams) + ", expected an array");
  if (cams.empty()) throw InputError(source + ": 'cameras' is empty");
  CameraSet out;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const std::string name = (cams[i].is_object() && cams[i].contains("name") && cams[i]["name"].is_string())
                                 ? cams[i]["name"].get<std::string>()
                                 : "cam" + std::to_string(i);
    out.push_back(cameraFromJson(cams[i], source + ": camera " + std::to_string(i) + " '" + name + "'", name));
  }
  checkDistinctCameras(out, source);
  return out;
}

CameraSet readCameraSetJson(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError("cannot open calibration file " + path);
  std::ostringstream text;
  text << in.rdbuf();
  return parseCameraSetJson(text.str(), path);
}

std::string formatCameraSetJson(const CameraSet& cameras) {
  json doc;
  doc["cameras"] = json::array();
  for (const Camera& c : cameras) {
    json cam;
    cam["name"] = c.name;
    cam["size"] = {c.width, c.height};
    cam["matrix"] = json::array();
    for (int r = 0; r < 3; ++r) cam["matrix"].push_back({c.K(r, 0), c.K(r, 1), c.K(r, 2)});
    cam["distortions"] = {c.dist[0], c.dist[1], c.dist[2], c.dist[3], c.dist[4]};
    const Eigen::Vector3d r = rodriguesFromRotation(c.R_CW);
    cam["rotation"] = {r.x(), r.y(), r.z()};
    cam["translation"] = {c.p_CW.x(), c.p_CW.y(), c.p_CW.z()};
    doc["cameras"].push_back(cam);
  }
  return doc.dump(1);
}

}  // namespace nao
