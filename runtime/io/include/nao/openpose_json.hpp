// One OpenPose keypoint frame (`--write_json`: one JSON file per frame per camera,
// docs/formats.md), parsed by nao_rt's live camera reader thread and by the toolchain alike.
//
// Every layout is mapped onto the BODY_25 indices of nao/body25.hpp (plus the four right-hand
// points), so nothing downstream knows which layout a file used:
//   - BODY_25: identity;
//   - BODY_25B: COCO order for points 0..16, 17 UpperNeck -> Neck (it sits a few cm above
//     BODY_25's Neck; the torso frame does not use Neck), 18 HeadTop dropped, 19..24 feet as in
//     BODY_25. BODY_25B has no MidHip: the reader leaves it undetected and triangulation sets
//     it to the mean of the two 3D hips (exact, unlike the mean of projected hips).
// A point is "not detected" (confidence 0) when OpenPose wrote it as 0,0,0 (confidence 0, or
// the pixel exactly 0,0). Nothing here invents a keypoint. Not real-time code: parsing
// allocates and throws InputError (reader thread or configure time).
#pragma once

#include "nao/body25.hpp"

#include <Eigen/Core>

#include <array>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace nao {

/// Body layout of pose_keypoints_2d; nothing in a file names it, so the user chooses.
enum class PoseFormat { kBody25, kBody25B };

/// "body25" or "body25b" -> format; nullopt for anything else.
std::optional<PoseFormat> poseFormatFromName(std::string_view name);
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

/// Frame index of an OpenPose file name (`<name>_<12 digits>_keypoints.json`, as OpenPose names
/// a video's frames, `<12 digits>_keypoints.json`, as it names a camera's, or
/// `<name>.<digits>.json`, at most 18 digits); nullopt for any other name.
std::optional<long long> openPoseFrameIndex(std::string_view file_name);

/// Parses one OpenPose JSON document. `source` names it in error messages. Throws InputError
/// (one line naming the source, the person and the problem) for malformed JSON, NaN/Infinity,
/// a missing or non-array `people`, a keypoint array of the wrong length, a non-number or
/// non-finite value, or a negative confidence. A confidence above 1 (real OpenPose output holds
/// values slightly above 1) is read as 1. An empty `people` array is valid. A file cut short
/// (half written) never parses: a JSON document has no complete prefix.
std::vector<Person2d> parseOpenPoseFrame(const std::string& text, PoseFormat format, const std::string& source);

/// OpenPose JSON text for `people` written in `format`'s layout (the inverse of the reader's
/// mapping; BODY_25B's HeadTop is written 0,0,0). Hand points are written as a 21-point
/// right-hand array when any of them is detected. Used by tests and synthetic data.
std::string formatOpenPoseJson(const std::vector<Person2d>& people, PoseFormat format);

}  // namespace nao
