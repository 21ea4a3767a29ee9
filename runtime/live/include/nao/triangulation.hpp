// Multi-camera triangulation of one OpenPose capture frame into a 3D skeleton: the
// per-frame core shared by nao_rt's live camera source (nao/live_camera.hpp) and the
// toolchain's offline triangulation of whole recordings (nao/tools/triangulate.hpp, which adds
// the sequence rules: bone lengths over the capture, gap interpolation, resampling).
//
// Per capture frame:
//  1. Subject selection by multi-view consistency. For every pair of cameras and every pair of
//     people in them, the upper-body points (Nose, Neck, shoulders, elbows, wrists, hips) seen
//     by both are triangulated; a pairing is a candidate when >= 3 points agree (reprojection
//     error <= outlier_px) and their median reprojection error is <= subject_px. Each further
//     camera contributes the person whose points reproject best (median <= subject_px, >= 3
//     points), else the person with the most agreeing points (>= 3 and >= 40 % of those
//     compared: the same body with a limb swapped), or nobody. Among candidates, those whose 3D
//     centre (torso points) lies within subject_max_jump_m of the last frame's subject are
//     preferred (continuity). The score of a candidate is its number of consistent (camera,
//     point) detections; among the candidates scoring >= 3/4 of the best, the winner is the
//     one whose centre appears closest to the image centres (cameras frame their subject), then
//     the higher score, then lower indices. No candidate -> the whole frame is missing. People
//     order and person_id play no role.
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
//  4. BODY_25B: MidHip = mean of the two 3D hips when both are valid (completeMidHip).
// The bone-length rule (bad bones against reference lengths) is per frame here; the offline
// form takes the reference lengths from the whole capture, the live form from its first
// seconds.
//
// Not real-time code: it runs on the live camera's reader thread (and offline) and allocates
// per frame (people lists, observation sets, TinySolver's dynamic residuals). Deterministic:
// the same frames in the same order give bitwise-equal points.
#pragma once

#include "nao/body25.hpp"
#include "nao/camera.hpp"
#include "nao/openpose_json.hpp"

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

namespace nao {

/// Per-frame settings of the triangulation (the toolchain's TriangulateOptions extends them).
struct TriangulationParams {
  double min_confidence = 0.05;     ///< detections below are not used
  double outlier_px = 10.0;         ///< max reprojection error of an accepted observation, px (1080p; scaled up with the image)
  double subject_px = 15.0;         ///< max median reprojection error of a person match, px (1080p; scaled likewise)
  double subject_max_jump_m = 0.5;  ///< continuity gate for the subject's torso centre, m
  int max_refine_iterations = 30;   ///< Ceres iteration cap per point
};

/// How far back a point's last estimate still breaks ties between camera sets, s.
inline constexpr double kTriangulationContinuity_s = 0.25;

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
/// `previous_W`, the point's latest estimate of the last kTriangulationContinuity_s, breaks
/// ties between equally large agreeing camera sets (the nearer wins).
PointEstimate triangulatePoint(const CameraSet& cameras, std::vector<Observation> obs, const TriangulationParams& opt,
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
                            const std::optional<Eigen::Vector3d>& previous_centre_W, const TriangulationParams& opt);

/// What the triangulation of one frame carries to the next: the subject's last centre and each
/// point's latest estimate (the continuity rules of the file comment). Build one per capture.
struct TriangulationState {
  std::optional<Eigen::Vector3d> previous_centre_W;
  std::array<Eigen::Vector3d, kNumSkeletonPoints> last_p_W;  ///< latest valid estimate per point
  std::array<double, kNumSkeletonPoints> last_t_s;           ///< its time, s (-inf: none yet)
  TriangulationState();
};

/// Forgets everything (a new capture, or the capture restarted).
void resetTriangulationState(TriangulationState& state);

/// What triangulateFrame did (for reports and counters).
struct FrameTriangulation {
  SubjectChoice subject;                              ///< found == false: nobody, every point missing
  int n_observations_rejected = 0;                    ///< camera observations dropped as outliers
  int n_points_inconsistent = 0;                      ///< >= 2 views that never agreed
  std::array<double, kNumSkeletonPoints> rms_px{};    ///< per valid point, RMS reprojection error, px
};

/// Triangulates one capture frame at time t_s (s; later than the state's previous frame):
/// subject selection, then every point with camera consensus (file comment, steps 1-3).
/// `people[c]` is camera c's people (an empty list when the camera has no file for the frame).
/// Writes every field of `out` (t_s, p_W and ok; views and reprojection_px of valid points;
/// interpolated false) and updates `state`. Does not set MidHip from the hips (completeMidHip).
FrameTriangulation triangulateFrame(const CameraSet& cameras, const std::vector<const std::vector<Person2d>*>& people,
                                    double t_s, const TriangulationParams& opt, TriangulationState& state,
                                    SkeletonFrame& out);

/// BODY_25B has no MidHip: sets it to the mean of the 3D hips when both are valid (exact, unlike
/// the mean of projected hips); interpolated / views / reprojection_px from both hips.
void completeMidHip(SkeletonFrame& frame);

/// Rigid segments of a human checked by the bone-length rule.
inline constexpr std::array<std::pair<int, int>, 20> kSkeletonBones = {{
    {kNose, kNeck},        {kNeck, kRShoulder},  {kNeck, kLShoulder},   {kRShoulder, kLShoulder},
    {kRShoulder, kRElbow}, {kRElbow, kRWrist},   {kLShoulder, kLElbow}, {kLElbow, kLWrist},
    {kRShoulder, kRHip},   {kLShoulder, kLHip},  {kRHip, kLHip},        {kRHip, kRKnee},
    {kRKnee, kRAnkle},     {kLHip, kLKnee},      {kLKnee, kLAnkle},     {kRWrist, kRHand9},
    {kRHand0, kRHand5},    {kRHand0, kRHand9},   {kRHand0, kRHand17},   {kRHand5, kRHand17},
}};
inline constexpr int kNumSkeletonBones = static_cast<int>(kSkeletonBones.size());

/// A bone is checked once it has this many samples and a reference length of at least
/// kMinBoneLength_m (shorter bones are too noisy to judge).
inline constexpr int kMinBoneSamples = 5;
inline constexpr double kMinBoneLength_m = 0.05;

/// Reference bone lengths of a subject: per bone of kSkeletonBones its median length over the
/// frames where both ends are valid, and whether it is checked (>= 5 samples, median >= 5 cm:
/// shorter bones are too noisy to judge).
struct BoneLengths {
  std::array<double, kNumSkeletonBones> median_m{};
  std::array<int, kNumSkeletonBones> n_samples{};
  std::array<bool, kNumSkeletonBones> checked{};
};

/// Median bone lengths over frames[0, n) (see BoneLengths).
BoneLengths medianBoneLengths(const SkeletonFrame* frames, std::size_t n);

/// The bone-length rule on one frame: a checked bone whose length differs from its reference
/// by more than max(tolerance * reference, 5 cm) is bad; greedily, the point(s) with the most
/// bad bones (all of their checked bones bad) are marked missing (ok = false), until no point
/// has all its bones bad. Catches what geometry cannot with two cameras (a wrong keypoint
/// moved along its epipolar line). Returns how many points it marked missing.
int rejectBoneOutliers(SkeletonFrame& frame, const BoneLengths& bones, double tolerance);

/// What a frame's points were triangulated from: the cameras, each camera's people and the
/// subject's index in them (FrameTriangulation::subject.person). Borrowed, not owned.
struct FrameObservations {
  const CameraSet* cameras = nullptr;
  const std::vector<const std::vector<Person2d>*>* people = nullptr;
  const std::vector<int>* subject_person = nullptr;  ///< per camera, -1: none
};

/// Bone-length consistency of the right arm. Shoulder, elbow and wrist are refitted together
/// (TinySolver, autodiff, iteration cap) on the confidence-weighted pixel reprojection error of
/// the cameras each was triangulated from (SkeletonFrame::views), plus, per arm bone (upper
/// arm, forearm), px_per_m * (its length - its reference length): a bone 1 cm off the
/// reference costs as much as px_per_m / 100 px of reprojection error. With two cameras a
/// point is least certain along the cameras' common depth, and that is where the bone
/// residual moves it. Runs when the three points are measured (ok, not interpolated), both
/// bones have a checked reference, and px_per_m > 0; the fit replaces them only if every
/// point stays in front of its cameras and the total cost fell. Returns true if it did.
bool fitArmBoneLengths(const FrameObservations& observations, const BoneLengths& bones, double px_per_m,
                       int max_iterations, SkeletonFrame& frame);

}  // namespace nao
