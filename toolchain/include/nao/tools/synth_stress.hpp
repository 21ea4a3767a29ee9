// Stress recordings for triangulation tests: a synthesised demonstration seen by >= 4 cameras
// with the faults real multi-camera OpenPose data has and the default synthesiser does not
// model (docs/synth.md "Stress recordings"):
//  - a second person walking back and forth in front of the subject (detected as a separate
//    person; the nearer person hides the other's points it covers in a camera's image);
//  - left/right arm swaps (shoulder, elbow, wrist labels) in bursts in one camera;
//  - a wrong but confident arm keypoint now and then in another camera;
//  - independent per-camera dropouts.
// The people of a frame file are in random order. Everything is a deterministic function of the
// demonstration and StressOptions::seed; the default synthesiser's output is not affected.
#pragma once

#include "nao/tools/openpose.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

struct StressOptions {
  int n_cameras = 4;             ///< >= 2, spread over -65..+65 deg around the subject's front
  double fps = 60.0;             ///< capture rate; the truth is interpolated from the demonstration's 30 Hz
  int n_frames = 0;              ///< frames to render from the start; 0: the whole demonstration
  bool bystander = true;         ///< a second person crossing in front of the subject
  int swap_camera = 1;           ///< camera with left/right arm swaps, -1: none
  double swap_fraction = 0.3;    ///< share of 0.5 s blocks in which that camera swaps
  int wrong_camera = 2;          ///< camera with wrong confident arm keypoints, -1: none
  double wrong_prob = 0.15;      ///< per frame: one arm keypoint 40-150 px off, confidence 0.95
  double dropout_prob = 0.08;    ///< per camera, point and frame
  // Swaps, wrong keypoints and dropouts never leave a right-arm point (shoulder, elbow, wrist)
  // with fewer than 2 correct views; they are skipped where they would.
  double pixel_sigma_px = 1.5;   ///< pixel noise (hand points x1.5)
  std::uint64_t seed = 1;
};

/// A rendered stress recording. Frame k is at t = k / fps and has file index k.
struct StressScene {
  std::string name;
  double fps = 60.0;
  CameraSet cameras;               ///< 1920 x 1080, world -> camera
  Skeleton truth;                  ///< the subject, every point valid
  Skeleton bystander;              ///< the second person (empty without one)
  std::vector<CameraKeypoints> keypoints;  ///< per camera, one KeypointFrame per frame (BODY_25 + hand points)
  /// [frame][camera]: index of the subject's / the bystander's detection in that frame's people, -1: not detected.
  std::vector<std::vector<int>> subject_index, bystander_index;
  /// [frame][point]: cameras whose subject detection of the point is correct (bit c = camera c):
  /// seen, not hidden, not swapped, not the wrong keypoint.
  std::vector<std::array<std::uint32_t, kNumSkeletonPoints>> correct_views;
  int n_hidden_points = 0;    ///< subject detections hidden by the second person (all frames and cameras)
  int n_swapped_frames = 0;   ///< frames in which swap_camera swapped the arms
  int n_wrong_keypoints = 0;  ///< wrong confident keypoints placed in wrong_camera
};

/// Renders demo's motion as a stress recording. Throws UserError for n_cameras < 2 or > 16, a
/// fault camera index >= n_cameras, or a non-positive fps.
StressScene renderStressScene(const SynthDemo& demo, const StressOptions& opt);

/// The regime of a real detector, whose confidence says how far off it is: every detection's
/// confidence redrawn uniformly in [0.2, 0.95] and its pixel moved by N(0, (12 px (1 - c))^2) per
/// axis, seeded. Undetected points keep their state (the draws are made for them too, so the
/// noise of a point does not depend on which others were detected).
void addDetectorNoise(StressScene& scene, std::uint64_t seed);

/// Writes DIR/<scene.name>/: cam0/ .. camN/ (OpenPose JSON, BODY_25, all people of a frame),
/// calibration.json and truth.csv (the subject, skeleton CSV). Throws UserError on I/O failure.
void writeStressScene(const StressScene& scene, const std::string& out_dir);

}  // namespace nao::tools
