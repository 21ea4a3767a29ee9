// Triangulation from files: a calibration file (JSON or TOML) and one OpenPose keypoint folder
// per camera (nao_toolchain triangulate). Apart from triangulate.cpp because reading calibration
// files needs toml++, which nao_rt's reference library (nao_reference) does not link.
#include "nao/tools/calibration.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/triangulate.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace nao::tools {

namespace fs = std::filesystem;

Skeleton triangulateFolders(const std::vector<std::string>& camera_dirs, const std::string& calibration_path,
                            const TriangulateOptions& opt, TriangulationReport* report) {
  const CameraSet cameras = readCalibration(calibration_path);
  if (cameras.size() != camera_dirs.size())
    throw UserError("calibration " + calibration_path + " has " + std::to_string(cameras.size()) + " cameras but " +
                    std::to_string(camera_dirs.size()) + " keypoint folders were given (cameras pair with folders in order)");
  if (!(opt.rate_hz > 0.0) || !std::isfinite(opt.rate_hz))
    throw UserError("--rate must be a positive number of samples per second");
  std::vector<CameraKeypoints> keypoints;
  for (const std::string& dir : camera_dirs) keypoints.push_back(readOpenPoseFolder(dir, opt.format));
  return resampleSkeleton(triangulateCapture(cameras, keypoints, opt, report), opt.rate_hz, opt.fps);
}

std::vector<std::string> demoCameraDirs(const std::string& demo_dir) {
  std::error_code ec;
  if (!fs::is_directory(demo_dir, ec)) throw UserError("demonstration folder " + demo_dir + " does not exist");
  std::vector<std::pair<long long, std::string>> dirs;
  for (const fs::directory_entry& e : fs::directory_iterator(demo_dir)) {
    const std::string name = e.path().filename().string();
    if (!e.is_directory() || name.compare(0, 3, "cam") != 0) continue;
    const std::string suffix = name.substr(3);
    const bool numbered = !suffix.empty() && suffix.size() < 18 &&
                          std::all_of(suffix.begin(), suffix.end(), [](char c) { return c >= '0' && c <= '9'; });
    dirs.emplace_back(numbered ? std::stoll(suffix) : std::numeric_limits<long long>::max(), e.path().string());
  }
  if (dirs.empty()) throw UserError(demo_dir + ": no cam*/ keypoint folders (expected cam0/, cam1/, ...)");
  std::sort(dirs.begin(), dirs.end());
  std::vector<std::string> out;
  for (auto& d : dirs) out.push_back(std::move(d.second));
  return out;
}

std::string demoCalibration(const std::string& demo_dir) {
  const fs::path dir(demo_dir);
  for (const fs::path& where : {dir, dir.parent_path()})
    for (const char* name : {"calibration.json", "calibration.toml"}) {
      std::error_code ec;
      if (fs::is_regular_file(where / name, ec)) return (where / name).string();
    }
  throw UserError(demo_dir + ": no calibration.json or calibration.toml in the recording's folder or the one above it");
}

Skeleton triangulateDemo(const std::string& demo_dir, const TriangulateOptions& opt, TriangulationReport* report) {
  // The camera folders first: a folder without them is not a recording, whatever else it has.
  const std::vector<std::string> cams = demoCameraDirs(demo_dir);
  return triangulateFolders(cams, demoCalibration(demo_dir), opt, report);
}

TriangulateOptions recordingOptions() {
  TriangulateOptions o;
  o.zero_lag_sigma_s = 0.05;
  o.bone_fit_px_per_m = 300.0;
  return o;
}

}  // namespace nao::tools
