#include "nao/live_skeleton.hpp"
#include "nao/median.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kTimeEps = 1e-9;

// Bone references from the window's samples (BoneLengths' rule).
void updateBoneReferences(LiveSkeletonState& state) {
  for (std::size_t b = 0; b < kSkeletonBones.size(); ++b) {
    const std::vector<double>& samples = state.bone_samples[b];
    state.bones.median_m[b] = median(samples);
    state.bones.n_samples[b] = static_cast<int>(samples.size());
    state.bones.checked[b] =
        static_cast<int>(samples.size()) >= kMinBoneSamples && state.bones.median_m[b] >= kMinBoneLength_m;
  }
}

}  // namespace

void resetLiveSkeleton(const LiveSkeletonParams& params, double fps, LiveSkeletonState& state) {
  const auto window_frames = static_cast<std::size_t>(std::ceil(std::max(params.reference_window_s, 0.0) * fps)) + 1;
  for (std::vector<double>& s : state.bone_samples) {
    s.clear();
    s.reserve(window_frames);
  }
  state.bone_window_end_s.fill(kInf);
  state.bones = BoneLengths{};
  resetSkeletonLowPass(state.low_pass);
  state.last_p_W.fill(Eigen::Vector3d::Zero());
  state.last_t_s.fill(-kInf);
  resetHumanArm(state.arm);
  for (std::vector<double>* v : {&state.upper_m, &state.forearm_m, &state.hand_m}) {
    v->clear();
    v->reserve(std::max<std::size_t>(window_frames, kMinScaleFrames));
  }
  state.scale_window_end_s = kInf;
  state.human_scale_m = params.human_scale_m > 0.0 ? params.human_scale_m : 0.0;
  state.hand_length_m = 0.0;
  state.current_scale_m = state.human_scale_m;
  state.current_hand_m = 0.0;
}

LiveSkeletonStep advanceLiveSkeleton(const LiveSkeletonParams& params, LiveSkeletonState& state, SkeletonFrame& frame,
                                     const FrameObservations* observations) {
  LiveSkeletonStep step;
  const double t = frame.t_s;

  // 1. Bone-length rule, then this frame's lengths join the references while their windows last.
  if (params.check_bone_lengths) step.n_bone_rejections = rejectBoneOutliers(frame, state.bones, params.bone_tolerance);
  bool references_changed = false;
  for (std::size_t b = 0; b < kSkeletonBones.size(); ++b) {
    const auto [i, j] = kSkeletonBones[b];
    if (!frame.ok[i] || !frame.ok[j]) continue;
    if (state.bone_window_end_s[b] == kInf) state.bone_window_end_s[b] = t + params.reference_window_s;
    if (t > state.bone_window_end_s[b] + kTimeEps) continue;
    state.bone_samples[b].push_back((frame.p_W[i] - frame.p_W[j]).norm());
    references_changed = true;
  }
  if (references_changed) updateBoneReferences(state);
  if (observations != nullptr)
    step.bone_fit = fitArmBoneLengths(*observations, state.bones, params.bone_fit_px_per_m, params.bone_fit_iterations, frame);

  // 2. Causal low-pass of the measured points.
  lowPassSkeleton(params.low_pass, state.low_pass, frame);

  // 3. Gap bridge: hold a point's last measurement across a short gap.
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    if (frame.ok[i]) {
      state.last_p_W[i] = frame.p_W[i];
      state.last_t_s[i] = t;
    } else if (params.max_gap_s > 0.0 && t - state.last_t_s[i] <= params.max_gap_s + kTimeEps) {
      frame.p_W[i] = state.last_p_W[i];
      frame.ok[i] = true;
      frame.interpolated[i] = true;
      frame.views[i] = 0;
      frame.reprojection_px[i] = 0.0f;
      ++step.n_bridged;
    }
  }

  // 4. BODY_25B's MidHip.
  if (params.format == PoseFormat::kBody25B) completeMidHip(frame);

  // 5. Human scale from the first seconds of measured arm frames.
  if (state.human_scale_m <= 0.0) {
    SkeletonFrame measured = frame;
    for (int i = 0; i < kNumSkeletonPoints; ++i) measured.ok[i] = frame.ok[i] && !frame.interpolated[i];
    const HumanKinematicsConfig per_frame;  // scale_m = 0, hand_length_m = 0: this frame's own lengths
    humanArmKinematics(per_frame, state.arm, measured);
    if (state.arm.valid) {
      if (state.scale_window_end_s == kInf) state.scale_window_end_s = t + params.reference_window_s;
      state.upper_m.push_back(state.arm.l_upper_m);
      state.forearm_m.push_back(state.arm.l_forearm_m);
      if (state.arm.hand_seen) state.hand_m.push_back(state.arm.l_hand_m);
    }
    if (state.arm.valid) {
      // The estimate's rule over the frames so far: provisional until the window is over.
      const double upper = median(state.upper_m), forearm = median(state.forearm_m);
      const double hand = state.hand_m.empty() ? per_frame.hand_to_forearm * forearm : median(state.hand_m);
      state.current_scale_m = upper + forearm + hand;
      state.current_hand_m = hand;
    }
    if (t >= state.scale_window_end_s - kTimeEps && static_cast<int>(state.upper_m.size()) >= kMinScaleFrames) {
      const double upper = median(state.upper_m), forearm = median(state.forearm_m);
      const double hand = state.hand_m.empty() ? per_frame.hand_to_forearm * forearm : median(state.hand_m);
      state.human_scale_m = upper + forearm + hand;
      state.hand_length_m = hand;
      state.current_scale_m = state.human_scale_m;
      state.current_hand_m = state.hand_length_m;
      step.scale_fixed = true;
    }
  }
  return step;
}

}  // namespace nao
