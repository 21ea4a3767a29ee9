// What the live camera source does to each triangulated frame before the control thread may
// take it (reader thread, in capture order), all causal: nothing waits for a later frame.
//  1. Bone-length rule (nao::rejectBoneOutliers) against reference lengths: each bone's median
//     over the subject's first reference_window_s (from its first frame with the bone seen);
//     within that window the medians of the frames so far. Offline the reference is the whole
//     capture's median; live it cannot be.
//     Then the arm's bone-length consistency against those references (fitArmBoneLengths),
//     when the frame's observations are given.
//  2. Causal low-pass of each measured point (SkeletonLowPass).
//  3. Gap bridge: a point missing for at most max_gap_s since its last measurement keeps that
//     last (filtered) position, flagged interpolated; longer gaps stay missing. Offline, gaps
//     are interpolated between both ends instead, which a live source cannot do.
//  4. BODY_25B: MidHip from the hips (completeMidHip).
//  5. Human scale d_h: unless given (human_scale_m > 0), the rule of the toolchain's
//     estimateHumanArmLengths over a window: per-segment medians (upper arm, forearm, hand) over
//     the frames with a measured arm in the first reference_window_s after the first one (and
//     at least kMinScaleFrames frames), d_h = their sum; the hand segment is 0.29 x forearm when
//     the hand was never seen. Fixed from then on; 0 until then. Until it is fixed, the same
//     medians over the frames so far are the provisional d_h a consumer may scale with
//     (current_scale_m: nao_rt's live reference does, so it imitates from the first frame).
// Not real-time code; allocation happens at configure time (resetLiveSkeleton reserves the
// windows) and, beyond the reserve, on the reader thread.
#pragma once

#include "nao/body25.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/skeleton_filter.hpp"
#include "nao/triangulation.hpp"

#include <array>
#include <cstdint>
#include <vector>

namespace nao {

/// Frames with a measured arm the scale estimate needs at least (more if the window has fewer).
inline constexpr int kMinScaleFrames = 5;

struct LiveSkeletonParams {
  PoseFormat format = PoseFormat::kBody25;
  double max_gap_s = 0.2;              ///< longest gap of a point that is bridged (held), s; 0: none
  bool check_bone_lengths = true;      ///< apply the bone-length rule
  double bone_tolerance = 0.25;        ///< relative bone-length deviation marked bad
  double reference_window_s = 3.0;     ///< bone references and d_h from the subject's first seconds, s
  double human_scale_m = 0.0;          ///< > 0: d_h given (no estimate)
  double bone_fit_px_per_m = 300.0;    ///< step 1's arm bone-length fit (1 cm off costs 3 px); 0: none
  int bone_fit_iterations = 30;        ///< its iteration cap
  /// Step 2: One Euro at 4 Hz at rest, +2 Hz per m/s (bench/results/triangulation_accuracy.txt).
  SkeletonLowPassParams low_pass{4.0, 2.0, 1.0, 0.2};
};

/// Everything the steps carry from frame to frame. One per capture (resetLiveSkeleton).
struct LiveSkeletonState {
  // 1. bone references
  std::array<std::vector<double>, kNumSkeletonBones> bone_samples;
  std::array<double, kNumSkeletonBones> bone_window_end_s{};  ///< per bone, end of its window (inf: not started)
  BoneLengths bones;
  // 2.
  SkeletonLowPass low_pass;
  // 3. last measured (filtered) position of each point
  std::array<Eigen::Vector3d, kNumSkeletonPoints> last_p_W;
  std::array<double, kNumSkeletonPoints> last_t_s{};
  // 5. scale
  HumanArmData arm;
  std::vector<double> upper_m, forearm_m, hand_m;
  double scale_window_end_s = 0.0;  ///< inf until the first measured arm
  double human_scale_m = 0.0;       ///< d_h once fixed (or given), else 0
  double hand_length_m = 0.0;       ///< hand segment once fixed (or given: 0, the per-frame rule)
  /// d_h to scale the last frame with: human_scale_m once fixed (or given); before that the
  /// estimate's medians over the measured frames so far; 0 before the first measured arm.
  double current_scale_m = 0.0;
  double current_hand_m = 0.0;      ///< its hand segment (0 with a given d_h: the per-frame rule)
};

/// Forgets everything (a new capture); reserves the windows for `fps` frames per second.
void resetLiveSkeleton(const LiveSkeletonParams& params, double fps, LiveSkeletonState& state);

/// What one step did.
struct LiveSkeletonStep {
  int n_bone_rejections = 0;  ///< points the bone-length rule marked missing
  int n_bridged = 0;          ///< points held across a gap
  bool bone_fit = false;      ///< the arm was refitted to its bone lengths
  bool scale_fixed = false;   ///< d_h was fixed by this frame
};

/// Steps 1-5 of the file comment on `frame` (triangulated, time frame.t_s later than the last
/// one), in place. `observations` (what the frame was triangulated from) enables the bone fit.
LiveSkeletonStep advanceLiveSkeleton(const LiveSkeletonParams& params, LiveSkeletonState& state, SkeletonFrame& frame,
                                     const FrameObservations* observations = nullptr);

}  // namespace nao
