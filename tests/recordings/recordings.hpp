// Test recordings of movements the synthesiser does not draw: a wave with the hand above the
// shoulder, a reach forward to shoulder height, and a lateral raise through the horizontal.
// Each is rendered into two calibrated 30 fps cameras as OpenPose BODY_25 JSON (with the four
// right-hand points 0, 5, 9, 17), in the layout `nao_toolchain triangulate --demo DIR` reads
// (docs/formats.md): DIR/<movement>_<index>/cam0/, cam1/, calibration.json, plus truth.csv
// (the skeleton CSV of the drawn points) and meta.json (the sampled parameters).
//
// The arm is described in Cartesian terms (upper-arm and forearm directions, the palm's
// normal, wrist rotations about the hand's own axes), not in NAO's joint convention, so the
// angles the toolchain extracts are measured, not replayed. Everything is a function of
// (movement, index, seed): one std::mt19937_64 per recording, raw 64-bit draws turned into
// uniform and normal variates by hand (the standard distributions differ between libraries),
// numbers printed with fixed precision, so a seed gives byte-identical files.
#pragma once

#include "nao/body25.hpp"
#include "nao/tools/camera.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

namespace nao::recordings {

/// The movements, in the order the CLI and the seeds know them.
inline constexpr std::array<const char*, 3> kMovementNames = {"wave", "reach", "side_raise"};

/// True for one of kMovementNames.
bool isMovement(const std::string& name);

/// One subject's body, m (joint centre to joint centre).
struct Subject {
  double stature_m = 0.0;
  double upper_arm_m = 0.0, forearm_m = 0.0, palm_m = 0.0, hand_breadth_m = 0.0;
  double shoulder_width_m = 0.0, hip_width_m = 0.0, trunk_m = 0.0, leg_m = 0.0;
};

/// Camera noise of one recording.
struct Noise {
  double pixel_sigma_px = 0.0;  ///< body keypoints; hand points 1.5 x
  double dropout = 0.0;         ///< per body keypoint and frame; hand points 3 x
  double hand_miss = 0.0;       ///< the hand detector misses the whole hand in this share of frames
  std::array<double, kNumBody25> confidence_body{};  ///< mean confidence per keypoint
  double confidence_hand = 0.0;
};

/// A recording in memory: what was drawn, and the cameras that saw it.
struct Recording {
  std::string name;      ///< "<movement>_<index, 3 digits>"
  std::string movement;  ///< one of kMovementNames
  int index = 0;
  std::uint64_t seed = 0, recording_seed = 0;
  double fps = 30.0;
  Subject subject;
  Noise noise;
  tools::CameraSet cameras;          ///< two cameras, world -> camera
  std::vector<SkeletonFrame> truth;  ///< world frame, every point valid
  /// Sampled motion parameters (name, value; angles in degrees, times in s), for meta.json.
  std::vector<std::pair<std::string, double>> params;
};

/// One camera's OpenPose detections of one frame: (x px, y px, confidence); 0,0,0 = not detected.
struct Detections {
  std::array<Eigen::Vector3d, kNumBody25> pose;
  std::array<Eigen::Vector3d, 21> hand_right;
};

/// The recording `index` of `movement` for `seed`. Pure function of its arguments; throws
/// std::invalid_argument for an unknown movement.
Recording generateRecording(const std::string& movement, int index, std::uint64_t seed);

/// What camera `camera` detects in every frame: projection with its distortion, pixel noise,
/// confidences, dropouts and missed hands from the camera's own seeded generator. Points
/// outside the image or behind the camera are 0,0,0.
std::vector<Detections> renderCamera(const Recording& recording, int camera);

/// Writes the recording into out_dir/<name>/ (cam0/, cam1/, calibration.json, truth.csv,
/// meta.json). Throws std::runtime_error naming the file that cannot be written.
void writeRecording(const Recording& recording, const std::string& out_dir);

struct Options {
  std::vector<std::string> movements = {kMovementNames.begin(), kMovementNames.end()};
  int per_movement = 8;
  std::uint64_t seed = 1;
  std::string out_dir;
};

/// Generates and writes per_movement recordings of every movement; one line per recording to
/// `progress`. Returns the number written. Throws std::invalid_argument for bad options.
int writeRecordings(const Options& options, std::ostream& progress);

}  // namespace nao::recordings
