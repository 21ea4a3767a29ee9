// Synthetic human demonstrations (offline): a 7-DoF human right arm with sampled
// anthropometrics draws the paper's three circle movements; the skeleton is projected into two
// virtual cameras as OpenPose BODY_25 (+ right hand) JSON, with the ground truth beside it.
//
// The arm model's joint convention is the one human_kinematics.hpp recovers (NAO's chain
// with human link lengths), so the truth angles are the model's own joint values. Everything
// is a deterministic function of (seed, movement, index): one local std::mt19937_64 per
// demonstration, numbers printed with fixed precision. docs/synth.md documents the model, the
// distributions and their sources; docs/formats.md the files.
#pragma once

#include "nao/body25.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/tools/camera.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

namespace nao::tools {

enum class Movement : int { kWholeArm = 0, kElbow = 1, kWrist = 2 };
inline constexpr std::array<const char*, 3> kMovementNames = {"whole_arm", "elbow", "wrist"};

/// "whole_arm" | "elbow" | "wrist" -> Movement; throws UserError otherwise.
Movement parseMovement(const std::string& name);

/// One subject's body, m. Segment lengths are joint-centre to joint-centre.
struct Anthropometrics {
  bool female = false;
  double stature_m = 0.0;
  double upper_arm_m = 0.0;       ///< shoulder -> elbow
  double forearm_m = 0.0;         ///< elbow -> wrist
  double hand_length_m = 0.0;     ///< wrist -> middle fingertip (not drawn; sets the palm)
  double shoulder_width_m = 0.0;  ///< between the shoulder joint centres
  double hip_width_m = 0.0;       ///< between the hip joint centres
  double trunk_m = 0.0;           ///< shoulder midpoint -> hip centre
  double leg_m = 0.0;             ///< hip centre height when standing upright
  /// Hand keypoints 0 (wrist), 5, 9, 17 in the hand frame K (x to the middle knuckle, y palm
  /// normal, z towards the thumb side).
  std::array<Eigen::Vector3d, 4> p_KHand;
  /// Hand segment of d_h: |centroid of the four hand points| (the endpoint), m.
  double hand_segment_m = 0.0;
  /// d_h = upper_arm + forearm + hand_segment.
  double scale_m() const { return upper_arm_m + forearm_m + hand_segment_m; }
};

/// Per-demonstration motion parameters (ranges in docs/synth.md).
struct MotionParams {
  double t_idle_start_s = 0, t_raise_s = 0, t_lower_s = 0, t_idle_end_s = 0;
  double circle_period_s = 0;   ///< one loop at full speed
  int n_loops = 0;
  double direction = 1.0;       ///< +1 / -1: sense of rotation
  double phase0_rad = 0.0;      ///< start angle on the circle
  double radius_rad = 0.0;      ///< cone half-angle of the circling segment
  double radius_m = 0.0;        ///< radius of the circle the circling segment's tip draws
  HumanJointVector q_rest = HumanJointVector::Zero();    ///< arm hanging (start and end)
  HumanJointVector q_centre = HumanJointVector::Zero();  ///< posture the circle is drawn around
  HumanJointVector drift_amp = HumanJointVector::Zero(), drift_hz = HumanJointVector::Zero(),
                   drift_phase = HumanJointVector::Zero();
  HumanJointVector tremor_amp = HumanJointVector::Zero(), tremor_hz = HumanJointVector::Zero(),
                   tremor_phase = HumanJointVector::Zero();
  Eigen::Vector3d sway_amp_m = Eigen::Vector3d::Zero();  ///< torso translation sway
  double sway_hz = 0.0, sway_phase = 0.0;
  double yaw_sway_rad = 0.0, lean_rad = 0.0;  ///< torso turning sway, forward lean
};

/// Camera noise model of one demonstration.
struct NoiseParams {
  double pixel_sigma_px = 0.0;       ///< body keypoints (hand: x1.5)
  double dropout_prob = 0.0;         ///< per body keypoint per frame (hand: x3)
  std::array<double, kNumBody25> confidence_body{};  ///< mean confidence per body keypoint
  double confidence_hand = 0.0;
};

/// A generated demonstration in memory: ground truth and cameras (no pixels yet).
struct SynthDemo {
  std::string name;  ///< "<movement>_<index 3 digits>"
  Movement movement = Movement::kWholeArm;
  int index = 0;
  std::uint64_t seed = 0;       ///< the run's seed
  std::uint64_t demo_seed = 0;  ///< derived per-demonstration seed
  bool noise_free = false;
  double fps = 30.0;
  Anthropometrics body;
  MotionParams motion;
  NoiseParams noise;
  CameraSet cameras;                   ///< two cameras, world -> camera
  std::vector<SkeletonFrame> truth;    ///< world frame, every point valid
  std::vector<HumanJointVector> q;     ///< model joint values per frame, rad
  std::vector<int> phase;              ///< 0 raise, 1 circle, 2 lower
};

/// One camera's OpenPose detections of one frame: (x px, y px, confidence); 0,0,0 = not detected.
struct OpenPoseFrame {
  std::array<Eigen::Vector3d, kNumBody25> pose;
  std::array<Eigen::Vector3d, 21> hand_right;
};

/// Per-demonstration seed derived from the run's seed, the movement and the index (splitmix64).
std::uint64_t demoSeed(std::uint64_t seed, Movement movement, int index);

/// Generates one demonstration's truth and cameras. Pure function of its arguments.
SynthDemo generateDemo(Movement movement, int index, std::uint64_t seed, bool noise_free);

/// Human arm forward model (docs/synth.md): world points of the right shoulder, elbow, wrist
/// and hand points 0/5/9/17 for joint values q, given the torso pose (R_WT, p_WT) and the
/// shoulder in the torso frame. Written as a chain of Eigen::AngleAxis products, independent
/// of the closed-form inverse in human_kinematics.cpp.
struct HumanArmPoints {
  Eigen::Vector3d p_WE, p_WR;
  std::array<Eigen::Vector3d, 4> p_WHand;
};
HumanArmPoints humanArmForward(const Anthropometrics& body, const Eigen::Matrix3d& R_WT, const Eigen::Vector3d& p_WT,
                               const Eigen::Vector3d& p_TS, const HumanJointVector& q);

/// The OpenPose detections of camera `camera_index` for every frame: projection with the
/// camera's distortion, pixel noise, confidence and dropouts from their own seeded generator
/// (none of these when demo.noise_free). Points outside the image or behind the camera are 0,0,0.
std::vector<OpenPoseFrame> renderCamera(const SynthDemo& demo, int camera_index);

/// Writes `demo` into DIR/<demo.name>/ (cam0/, cam1/, calibration.json, truth.csv,
/// truth_skeleton.csv, meta.json).
/// Throws UserError when a file cannot be written.
void writeDemo(const SynthDemo& demo, const std::string& out_dir);

/// Options of `nao_toolchain synth`.
struct SynthOptions {
  std::vector<Movement> movements = {Movement::kWholeArm, Movement::kElbow, Movement::kWrist};
  int per_movement = 80;
  std::uint64_t seed = 1;
  bool noise_free = false;
  std::string out_dir;
};

/// Generates and writes every demonstration; one progress line per demonstration to
/// `progress`. Returns the number written. Throws UserError on bad options or I/O failure.
int synthesise(const SynthOptions& options, std::ostream& progress);

}  // namespace nao::tools
