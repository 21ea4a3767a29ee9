// OpenPose keypoint files: one JSON file per frame, one folder per camera (docs/formats.md).
// One frame is parsed by the runtime (nao/openpose_json.hpp: the live camera reader uses the
// same parser); this adds what the offline pipeline needs: whole folders, sorted by frame index.
#pragma once

#include "nao/openpose_json.hpp"

#include <optional>
#include <string>
#include <vector>

namespace nao::tools {

using nao::formatOpenPoseJson;
using nao::kBody25bToSkeleton;
using nao::openPoseFrameIndex;
using nao::Person2d;
using nao::PoseFormat;
using nao::poseFormatName;

/// "body25" or "body25b" -> format. Throws UserError for anything else.
PoseFormat parsePoseFormat(const std::string& name);

/// One frame file of one camera.
struct KeypointFrame {
  std::string file;              ///< path it was read from
  long long index = 0;           ///< frame index parsed from the file name
  std::vector<Person2d> people;  ///< may be empty: nobody detected in this frame
};

/// All frames of one camera folder, sorted by frame index.
struct CameraKeypoints {
  std::string dir;
  std::vector<KeypointFrame> frames;
};

/// Parses one OpenPose JSON document (nao::parseOpenPoseFrame), throwing UserError instead of
/// InputError (same message: the source, the person and the problem).
std::vector<Person2d> parseOpenPoseJson(const std::string& text, PoseFormat format, const std::string& source);

/// Reads one OpenPose JSON file (see parseOpenPoseJson).
std::vector<Person2d> readOpenPoseFile(const std::string& path, PoseFormat format);

/// Reads every frame file of a camera folder, sorted by frame index; other files are ignored.
/// Throws UserError if the folder does not exist, holds no frame file, holds two files with
/// the same frame index, or any frame file is malformed.
CameraKeypoints readOpenPoseFolder(const std::string& dir, PoseFormat format);

}  // namespace nao::tools
