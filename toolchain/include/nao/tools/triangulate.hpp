// Multi-camera triangulation of OpenPose keypoints into a 3D skeleton (DESIGN section 4).
//
// Per capture frame:
//  1. Subject selection by multi-view consistency. For every pair of cameras and every pair of
//     people in them, the upper-body points (Nose, Neck, shoulders, elbows, wrists, hips) seen
//     by both are triangulated; a pairing is a candidate when >= 3 points agree (reprojection
//     error <= outlier_px) and their median reprojection error is <= subject_px. Each further
//     camera contributes the person whose points reproject best (median <= subject_px, >= 3
//     points), else the person with the most agreeing points (>= 3 and >= 40 % of those
//     compared: the same body with a limb swapped), or nobody. Among candidates, those whose 3D centre (torso points) lies within
//     subject_max_jump_m of the last frame's subject are preferred (continuity). The score of a
//     candidate is its number of consistent (camera, point) detections; among the candidates
//     scoring >= 3/4 of the best, the winner is the one whose centre appears closest to the
//     image centres (cameras frame their subject), then the higher score, then lower indices.
//     No candidate -> the whole frame is missing. People order and person_id play no role.
//  2. Per keypoint, the chosen people's detections with confidence >= min_confidence are
//     triangulated: confidence-weighted DLT on undistorted points, then Ceres (TinySolver,
//     autodiff, iteration cap) on the confidence-weighted pixel reprojection error; the refined
//     point replaces the DLT point only if it is in front of every camera and that error is
//     not higher.
//  3. Camera selection by consensus. A fit is consistent when every used camera sees the point
//     in front of it and reprojects it within its tolerance: outlier_px, given for a 1920 x 1080
//     image and scaled by the image diagonal for larger images (never below outlier_px). When
//     the fit of all n >= 3 cameras is inconsistent, every pair of cameras (n <= 8) proposes
//     the point of its two rays; the proposal that the most cameras agree with (within their
//     tolerance; ties: the one nearest the point's latest estimate of the last 0.25 s, else
//     the lower sum of squared errors; then the lower pair) wins, and its
//     consensus set is refitted and re-checked against all cameras until it no longer changes.
//     While that fit (or, above 8 cameras, the fit of all) is still inconsistent and >= 3
//     cameras remain, the camera whose removal gives the smallest worst-case reprojection error
//     of the others is dropped. Cameras not in the final fit count as rejected. A fit of 2
//     cameras that is inconsistent (the two rays do not meet: a wrong keypoint off the
//     epipolar line) makes the point missing: with two views one cannot tell which camera is
//     wrong, so no point is invented. Fewer than 2 usable views -> missing. The cameras used
//     (SkeletonFrame::views) and their RMS reprojection error are kept per point.
//  4. BODY_25B: MidHip = mean of the two 3D hips when both are valid.
// Over the sequence (capture rate), the bone-length rule catches what geometry cannot with two
// cameras (a wrong keypoint moved along its epipolar line): a bone whose length differs from
// its sequence median by more than max(bone_tolerance * median, 5 cm) is bad; greedily, the
// point with the most bad bones (all of its checked bones bad) is marked missing, until no
// point has all its bones bad. Bones need >= 5 valid samples and a median >= 5 cm.
// Gap policy (max_gap_s): a point missing for at most max_gap_s between two valid samples of
// it is interpolated linearly and flagged (SkeletonFrame::interpolated, CSV `_ok` = 2); longer
// gaps, and gaps that contain frame indices absent from every folder, stay missing.
// Frames pair across cameras by their file index (triangulateCapture); finally the sequence is
// resampled from fps to rate_hz (resampleSkeleton), never interpolating across absent frames.
#pragma once

#include "nao/body25.hpp"
#include "nao/tools/camera.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/skeleton_csv.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace nao::tools {

struct TriangulateOptions {
  PoseFormat format = PoseFormat::kBody25;
  double fps = 30.0;                ///< capture rate of the keypoint files, Hz
  double rate_hz = 10.0;            ///< output rate, Hz
  double min_confidence = 0.05;     ///< detections below are not used
  double outlier_px = 10.0;         ///< max reprojection error of an accepted observation, px (1080p; scaled up with the image)
  double subject_px = 15.0;         ///< max median reprojection error of a person match, px (1080p; scaled likewise)
  double max_gap_s = 0.2;           ///< longest gap of a point that is interpolated (flagged), s; 0: none
  double subject_max_jump_m = 0.5;  ///< continuity gate for the subject's torso centre, m
  bool check_bone_lengths = true;   ///< apply the bone-length rule over the sequence
  double bone_tolerance = 0.25;     ///< relative bone-length deviation marked bad
  int max_refine_iterations = 30;   ///< Ceres iteration cap per point
  std::function<void(int done, int total)> progress;  ///< after each frame read; total = frames read
};

/// What happened, for the CLI summary and the tests.
struct TriangulationReport {
  int n_frames = 0;                 ///< capture frames: indices from the first to the last frame file
  int n_frames_absent = 0;          ///< of those, indices no camera folder has a file for
  int n_frames_incomplete = 0;      ///< indices some camera folders have a file for and others not
  int n_frames_without_subject = 0; ///< no consistent person across >= 2 cameras (absent frames included)
  int n_points_valid = 0;           ///< valid points at capture rate (after the bone rule)
  int n_points_missing = 0;         ///< missing points at capture rate (absent frames included)
  int n_points_inconsistent = 0;    ///< >= 2 views that never agreed -> missing
  int n_observations_rejected = 0;  ///< camera observations dropped as outliers
  int n_bone_rejections = 0;        ///< points marked missing by the bone-length rule
  int n_points_interpolated = 0;    ///< missing points bridged by the gap policy (not in n_points_valid/missing)
  double median_reprojection_px = 0.0;  ///< over valid points, RMS over their cameras
  /// Per output frame of triangulateCapture (sorted present indices): per camera the index of
  /// the subject's detection in that camera's people, or -1.
  std::vector<std::vector<int>> subject_person;
};

/// One camera's detection of one point.
struct Observation {
  int camera = 0;                 ///< index into the CameraSet
  Eigen::Vector2d px;             ///< pixel (distorted image)
  double confidence = 1.0;        ///< weight, (0, 1]
};

/// A triangulated point.
struct PointEstimate {
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();  ///< world frame, m (meaningless when !ok)
  bool ok = false;
  int n_used = 0;              ///< cameras in the final fit
  int n_rejected = 0;          ///< cameras dropped by the outlier rule
  std::uint32_t views = 0;     ///< cameras in the final fit: bit c = Observation::camera c (c < 32)
  bool inconsistent = false;   ///< had >= 2 views but none agreed
  double rms_px = 0.0;         ///< RMS reprojection error over the used cameras
};

/// Normalised undistorted image coordinates (x/z, y/z) of pixel `px`: inverse of camera.hpp's
/// distort() and K by Newton iteration (to 1e-14 or 50 iterations).
Eigen::Vector2d undistortPixel(const Camera& cam, const Eigen::Vector2d& px);

/// Confidence-weighted linear (DLT) triangulation from >= 2 observations (rows scaled by
/// sqrt(confidence) * focal length). nullopt if degenerate (point at infinity).
std::optional<Eigen::Vector3d> triangulateDlt(const CameraSet& cameras, const std::vector<Observation>& obs);

/// Ceres refinement of p0_W on the confidence-weighted pixel reprojection error.
Eigen::Vector3d refineOnReprojection(const CameraSet& cameras, const std::vector<Observation>& obs,
                                     const Eigen::Vector3d& p0_W, int max_iterations);

/// One point from all its observations, with the camera selection of the file comment.
/// `previous_W`, the point's latest estimate (triangulateCapture: of the last 0.25 s), breaks ties between
/// equally large agreeing camera sets (the nearer wins).
PointEstimate triangulatePoint(const CameraSet& cameras, std::vector<Observation> obs, const TriangulateOptions& opt,
                               const std::optional<Eigen::Vector3d>& previous_W = std::nullopt);

/// Subject chosen in one frame: per camera the index into its people, or -1.
struct SubjectChoice {
  bool found = false;
  std::vector<int> person;                          ///< per camera
  int n_points = 0;                                 ///< consistent upper-body points
  double median_px = 0.0;
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();  ///< torso centre, m
};

/// Subject selection of the file comment. `people[c]` is camera c's people of this frame;
/// `previous_centre_W` is the last frame's subject centre, if any.
SubjectChoice chooseSubject(const CameraSet& cameras, const std::vector<const std::vector<Person2d>*>& people,
                            const std::optional<Eigen::Vector3d>& previous_centre_W, const TriangulateOptions& opt);

/// Triangulates a whole capture, applying the bone-length rule when enabled; no resampling.
/// Frames pair across cameras by KeypointFrame::index: one output frame per index present in
/// any camera (sorted), at t_s = (index - first index) / fps, so indices absent from every
/// folder leave a gap in time. A camera without a file for an index sees nobody in that frame
/// (with 2 cameras the frame has no subject; with 3+ the others still triangulate). Throws
/// UserError if fewer than 2 cameras, the camera and folder counts differ, a camera detects
/// nobody in any frame, a camera holds two frames with one index, or the indices span more
/// than 3 million frames or 24 h at fps.
Skeleton triangulateCapture(const CameraSet& cameras, const std::vector<CameraKeypoints>& keypoints,
                            const TriangulateOptions& opt, TriangulationReport* report = nullptr);

/// Bone-length rule of the file comment; returns how many points it marked missing.
int rejectBoneLengthOutliers(Skeleton& frames, double tolerance);

/// Gap policy of the file comment on capture frames at capture_fps: interpolates every gap of
/// a point that lasts at most max_gap_s (missing capture frames / capture_fps) between two
/// valid samples, with no absent frame index inside, and flags the filled points
/// (interpolated, views 0). Returns how many points it filled.
int fillShortGaps(Skeleton& frames, double max_gap_s, double capture_fps);

/// Resamples to rate_hz: times t0 + j / rate_hz up to the last input time. `frames` are capture
/// frames at capture_fps, possibly with gaps (absent frames). A time that falls on an input
/// sample (within 1e-9 s) copies it; otherwise each point is interpolated linearly between the
/// two neighbouring samples when both are valid and they are adjacent capture frames (at most
/// 1 / capture_fps apart), and is missing otherwise: nothing is invented inside a gap.
Skeleton resampleSkeleton(const Skeleton& frames, double rate_hz, double capture_fps);

/// From files (triangulate_files.cpp: nao_toolchain_lib only, it reads calibration files with
/// toml++). Folders (one per camera, in calibration order) + calibration file -> resampled skeleton.
Skeleton triangulateFolders(const std::vector<std::string>& camera_dirs, const std::string& calibration_path,
                            const TriangulateOptions& opt, TriangulationReport* report = nullptr);

/// A synthesiser demonstration folder: its cam*/ folders (sorted by camera number) and
/// calibration.json -> resampled skeleton.
Skeleton triangulateDemo(const std::string& demo_dir, const TriangulateOptions& opt,
                         TriangulationReport* report = nullptr);

/// The cam*/ folders of a demonstration, sorted by camera number.
std::vector<std::string> demoCameraDirs(const std::string& demo_dir);

}  // namespace nao::tools
