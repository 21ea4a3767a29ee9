// The human skeleton as OpenPose's BODY_25 layout names it, plus four right-hand points.
//
// Everything downstream of the keypoint reader uses these indices; the BODY_25B reader maps
// its own layout onto them. Shared by the runtime (live human frames) and the toolchain.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace nao {

/// BODY_25 keypoint indices (OpenPose output order).
enum Body25 : int {
  kNose = 0, kNeck, kRShoulder, kRElbow, kRWrist, kLShoulder, kLElbow, kLWrist, kMidHip, kRHip,
  kRKnee, kRAnkle, kLHip, kLKnee, kLAnkle, kREye, kLEye, kREar, kLEar, kLBigToe,
  kLSmallToe, kLHeel, kRBigToe, kRSmallToe, kRHeel,
};
inline constexpr int kNumBody25 = 25;

/// Right-hand points kept from OpenPose's 21-point hand model: wrist (0), index, middle and
/// little-finger knuckles (5, 9, 17). They give the hand's orientation when it is seen.
inline constexpr std::array<int, 4> kHandKeypointIds = {0, 5, 9, 17};
enum HandPoint : int { kRHand0 = kNumBody25, kRHand5, kRHand9, kRHand17 };

/// Points of a skeleton frame: the 25 body points, then the 4 hand points.
inline constexpr int kNumSkeletonPoints = kNumBody25 + 4;

inline constexpr std::array<const char*, kNumSkeletonPoints> kSkeletonPointNames = {
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "MidHip", "RHip",
    "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar", "LBigToe",
    "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel", "RHand0", "RHand5", "RHand9", "RHand17"};

/// One 3D skeleton sample. p_W[i] is point i in the world (calibration) frame, m; ok[i] is
/// false when the point was not seen by enough cameras (its position is then meaningless).
struct SkeletonFrame {
  double t_s = 0.0;
  std::array<Eigen::Vector3d, kNumSkeletonPoints> p_W;
  std::array<bool, kNumSkeletonPoints> ok{};
  /// Triangulation bookkeeping (the toolchain writes it, the runtime ignores it): per point,
  /// the cameras whose detections made it (bit c = camera c of the calibration; 0 when not
  /// triangulated), their RMS reprojection error (px), and whether the point was bridged
  /// across a short gap by interpolation instead of measured (skeleton CSV `_ok` = 2).
  std::array<std::uint32_t, kNumSkeletonPoints> views{};
  std::array<float, kNumSkeletonPoints> reprojection_px{};
  std::array<bool, kNumSkeletonPoints> interpolated{};
};

/// A skeleton sequence, one frame per sample.
using Skeleton = std::vector<SkeletonFrame>;

}  // namespace nao
