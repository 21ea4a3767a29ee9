#include "nao/tools/openpose.hpp"

#include "nao/input_error.hpp"
#include "nao/tools/command.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

}  // namespace

PoseFormat parsePoseFormat(const std::string& name) {
  if (const std::optional<PoseFormat> format = poseFormatFromName(name)) return *format;
  throw UserError("unknown keypoint format '" + name + "', expected body25 or body25b");
}

std::vector<Person2d> parseOpenPoseJson(const std::string& text, PoseFormat format, const std::string& source) {
  try {
    return parseOpenPoseFrame(text, format, source);
  } catch (const InputError& e) {
    throw UserError(e.what());
  }
}

std::vector<Person2d> readOpenPoseFile(const std::string& path, PoseFormat format) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw UserError("cannot open OpenPose file " + path);
  std::ostringstream text;
  text << in.rdbuf();
  return parseOpenPoseJson(text.str(), format, path);
}

CameraKeypoints readOpenPoseFolder(const std::string& dir, PoseFormat format) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw UserError("keypoint folder " + dir + " does not exist or is not a folder");
  std::map<long long, std::string> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const std::string name = entry.path().filename().string();
    const std::optional<long long> index = openPoseFrameIndex(name);
    if (!index) continue;
    const auto [it, inserted] = files.emplace(*index, entry.path().string());
    if (!inserted) {
      // Report the pair in a stable order whatever the directory order was.
      const std::string a = std::min(it->second, entry.path().string());
      const std::string b = std::max(it->second, entry.path().string());
      throw UserError(dir + ": two files for frame " + std::to_string(*index) + ": " + a + " and " + b);
    }
  }
  if (files.empty())
    throw UserError(dir + ": no OpenPose frame files ([<name>_]<12 digits>_keypoints.json or <name>.<digits>.json)");
  CameraKeypoints cam;
  cam.dir = dir;
  cam.frames.reserve(files.size());
  for (const auto& [index, path] : files) cam.frames.push_back({path, index, readOpenPoseFile(path, format)});
  return cam;
}

}  // namespace nao::tools
