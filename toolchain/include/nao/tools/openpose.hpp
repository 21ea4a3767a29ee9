// OpenPose keypoint files: one JSON file per frame, one folder per camera (docs/formats.md).
//
// Every layout is mapped onto the BODY_25 indices of nao/body25.hpp (plus the four right-hand
// points), so nothing downstream knows which layout a file used:
//   - BODY_25: identity;
//   - BODY_25B: COCO order for points 0..16, 17 UpperNeck -> Neck (it sits a few cm above
//     BODY_25's Neck; the torso frame does not use Neck), 18 HeadTop dropped, 19..24 feet as in
//     BODY_25. BODY_25B has no MidHip: the reader leaves it undetected and triangulation sets
//     it to the mean of the two 3D hips (exact, unlike the mean of projected hips).
// A point is "not detected" (confidence 0) when OpenPose wrote it as 0,0,0 (confidence 0, or
// the pixel exactly 0,0). Nothing here invents a keypoint.
#pragma once

#include "nao/body25.hpp"

#include <Eigen/Core>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace nao::tools {

/// Body layout of pose_keypoints_2d; nothing in a file names it, so the user chooses.
enum class PoseFormat { kBody25, kBody25B };

/// "body25" or "body25b" -> format. Throws UserError for anything else.
PoseFormat parsePoseFormat(const std::string& name);
const char* poseFormatName(PoseFormat format);

/// BODY_25B index k -> skeleton index (nao::Body25), -1 for points with no BODY_25 slot.
inline constexpr std::array<int, kNumBody25> kBody25bToSkeleton = {
    kNose,    kLEye,     kREye,  kLEar,  kREar,  kLShoulder, kRShoulder, kLElbow,
    kRElbow,  kLWrist,   kRWrist, kLHip, kRHip,  kLKnee,     kRKnee,     kLAnkle,
    kRAnkle,  kNeck /* 17 UpperNeck */,  -1 /* 18 HeadTop */, kLBigToe,  kLSmallToe,
    kLHeel,   kRBigToe,  kRSmallToe, kRHeel};

/// One person of one camera frame, in skeleton (BODY_25 + hand) indices.
struct Person2d {
  int person_id = -1;                                    ///< OpenPose's id, -1 when untracked
  std::array<Eigen::Vector2d, kNumSkeletonPoints> px;    ///< pixel coordinates (distorted image)
  std::array<double, kNumSkeletonPoints> confidence{};   ///< [0, 1] (file values > 1 clamped); 0 = not detected
  Person2d() { px.fill(Eigen::Vector2d::Zero()); }
  bool detected(int i) const { return confidence[i] > 0.0; }
};

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

/// Frame index of an OpenPose file name (`<name>_<12 digits>_keypoints.json` or
/// `<name>.<digits>.json`); nullopt for any other name.
std::optional<long long> openPoseFrameIndex(const std::string& file_name);

/// Parses one OpenPose JSON document. `source` names it in error messages. Throws UserError
/// (one line naming the source, the person and the problem) for malformed JSON, NaN/Infinity,
/// a missing or non-array `people`, a keypoint array of the wrong length, a non-number or
/// non-finite value, or a negative confidence. A confidence above 1 (real OpenPose output holds
/// values slightly above 1) is read as 1. An empty `people` array is valid.
std::vector<Person2d> parseOpenPoseJson(const std::string& text, PoseFormat format, const std::string& source);

/// Reads one OpenPose JSON file (see parseOpenPoseJson).
std::vector<Person2d> readOpenPoseFile(const std::string& path, PoseFormat format);

/// Reads every frame file of a camera folder, sorted by frame index; other files are ignored.
/// Throws UserError if the folder does not exist, holds no frame file, holds two files with
/// the same frame index, or any frame file is malformed.
CameraKeypoints readOpenPoseFolder(const std::string& dir, PoseFormat format);

/// OpenPose JSON text for `people` written in `format`'s layout (the inverse of the reader's
/// mapping; BODY_25B's HeadTop is written 0,0,0). Hand points are written as a 21-point
/// right-hand array when any of them is detected. Used by tests and synthetic data.
std::string formatOpenPoseJson(const std::vector<Person2d>& people, PoseFormat format);

}  // namespace nao::tools
