// Multi-camera triangulation of OpenPose keypoints into a 3D skeleton.
//
// The per-frame core (subject selection, DLT + Ceres refinement, camera consensus, MidHip of
// BODY_25B) is the runtime's (nao/triangulation.hpp), shared with nao_rt's live camera source;
// its file comment states the rules. This adds what needs the whole recording.
// Over the sequence (capture rate), the bone-length rule (nao::rejectBoneOutliers) catches what
// geometry cannot with two cameras (a wrong keypoint moved along its epipolar line), with each
// bone's median over the whole capture as its reference length.
// Gap policy (max_gap_s): a point missing for at most max_gap_s between two valid samples of
// it is interpolated linearly and flagged (SkeletonFrame::interpolated, CSV `_ok` = 2); longer
// gaps, and gaps that contain frame indices absent from every folder, stay missing.
// Frames pair across cameras by their file index (triangulateCapture); finally the sequence is
// resampled from fps to rate_hz (resampleSkeleton), never interpolating across absent frames.
#pragma once

#include "nao/body25.hpp"
#include "nao/triangulation.hpp"
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

/// Settings of the offline triangulation: the per-frame ones (nao::TriangulationParams:
/// min_confidence, outlier_px, subject_px, subject_max_jump_m, max_refine_iterations) and the
/// sequence ones.
struct TriangulateOptions : TriangulationParams {
  PoseFormat format = PoseFormat::kBody25;
  double fps = 30.0;                ///< capture rate of the keypoint files, Hz
  double rate_hz = 10.0;            ///< output rate, Hz
  double max_gap_s = 0.2;           ///< longest gap of a point that is interpolated (flagged), s; 0: none
  bool check_bone_lengths = true;   ///< apply the bone-length rule over the sequence
  double bone_tolerance = 0.25;     ///< relative bone-length deviation marked bad
  double bone_fit_px_per_m = 0.0;   ///< arm bone-length consistency (nao::fitArmBoneLengths) against the capture's medians; 0: none
  double zero_lag_sigma_s = 0.0;    ///< zero-lag smoothing of the measured points (smoothSkeletonZeroLag), s; 0: none
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
  int n_arm_bone_fits = 0;          ///< frames whose arm was refitted to its bone lengths (bone_fit_px_per_m)
  int n_points_interpolated = 0;    ///< missing points bridged by the gap policy (not in n_points_valid/missing)
  double median_reprojection_px = 0.0;  ///< over valid points, RMS over their cameras
  /// Per output frame of triangulateCapture (sorted present indices): per camera the index of
  /// the subject's detection in that camera's people, or -1.
  std::vector<std::vector<int>> subject_person;
};

using nao::chooseSubject;
using nao::Observation;
using nao::PointEstimate;
using nao::refineOnReprojection;
using nao::SubjectChoice;
using nao::triangulateDlt;
using nao::triangulatePoint;
using nao::undistortPixel;

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

/// Zero-lag low-pass over time (offline): every measured point (ok, not interpolated) is
/// replaced by the value at its own time of a straight line fitted by weighted least squares to
/// that point's measured samples within 3 sigma_s, weighted exp(-dt^2 / (2 sigma_s^2)) (local
/// linear regression with a Gaussian kernel: no lag, no bias at the ends of a run or for a
/// steady motion; -3 dB near 0.13 / sigma_s Hz). Frames further apart than 1.5 / capture_fps
/// (absent indices) split the runs. Points with fewer than 3 samples in reach are left alone.
/// Nothing happens for sigma_s <= 0. Returns how many points it changed.
int smoothSkeletonZeroLag(Skeleton& frames, double sigma_s, double capture_fps);

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

/// The calibration of a recording folder (docs/formats.md): calibration.json or calibration.toml
/// in it, else in the folder above it (one for all recordings). Throws UserError naming the folder.
std::string demoCalibration(const std::string& demo_dir);

/// What nao_toolchain triangulate does by default beside TriangulateOptions' own defaults: the
/// zero-lag low-pass (0.05 s) and the arm bone-length fit (300 px/m) - the recordings of a data set
/// and of an evaluation are triangulated alike.
TriangulateOptions recordingOptions();

/// A recording folder: its cam*/ folders (sorted by camera number) and its calibration
/// (demoCalibration) -> resampled skeleton.
Skeleton triangulateDemo(const std::string& demo_dir, const TriangulateOptions& opt,
                         TriangulationReport* report = nullptr);

/// The cam*/ folders of a demonstration, sorted by camera number.
std::vector<std::string> demoCameraDirs(const std::string& demo_dir);

}  // namespace nao::tools
