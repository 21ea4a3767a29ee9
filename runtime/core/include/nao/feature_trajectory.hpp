// The feature-extracted trajectory of a demonstration: its retargeted poses
// snapped to the movement's key poses and joined with the original segment timing by a
// critically damped blend. nao_rt scores a recorded reference against it; the toolchain's
// clustering writes it (features.csv) and trains on it. The controller feeds the policy the
// same blend online (kFeatureBlendPole). Configure-time code: allocates, throws InputError.
#pragma once

#include "nao/arm_model.hpp"

#include <vector>

namespace nao {

/// The pole of the key-pose blend that makes the feature-extracted trajectory (the
/// controller's online blend and KeyPoseBlend): f(t+1) = f(t) + v(t),
/// v(t) = pole² v(t−1) + (1 − pole)² (c(t) − f(t)), f(0) = c(0), v(−1) = 0.
inline constexpr double kFeatureBlendPole = 0.7;

/// Index of the centroid nearest to q (Euclidean in joint space; ties go to the lower index).
int nearestCentroid(const std::vector<JointVector>& centroids, const JointVector& q);

/// How a feature-extracted trajectory moves between key poses: once per 10 Hz tick,
///   v(t) = (1 − γ) v(t−1) + κ (c(t) − f(t)),   f(t+1) = f(t) + v(t),   v(−1) = 0,
/// with c(t) the key pose of the segment tick t is in. A critically damped second-order approach
/// with both poles at `pole` (γ = 1 − pole², κ = (1 − pole)²): smooth, no overshoot, and
/// causal — f(t+1) − f(t) is a function of (f(t), v(t−1), c(t)) alone, which are exactly the
/// policy's inputs (q, a(t−1), r), so the reference-conditioned policy can follow it.
/// After a key-pose change f(t) − c = e0 (1 + (1 − pole) n) poleⁿ (n ticks later).
struct KeyPoseBlend {
  double pole = kFeatureBlendPole;  ///< 0.7 per tick: 1 % of a step left after 19 ticks (1.9 s)
  double gamma() const { return 1.0 - pole * pole; }
  double kappa() const { return (1.0 - pole) * (1.0 - pole); }
  /// v(t) from v(t−1), f(t) and c(t).
  JointVector velocity(const JointVector& v_prev, const JointVector& f, const JointVector& c) const {
    return (1.0 - gamma()) * v_prev + kappa() * (c - f);
  }
};

/// Feature-extracted trajectory: the measured samples are labelled by nearest
/// centroid; each run of equal labels is a segment whose key pose is its centroid, in force from
/// the segment's first sample (the original segment timing); the trajectory starts at the first
/// key pose at rest and follows `blend` toward the key pose in force, one step per output
/// sample. One output pose per input sample (the samples are taken as consecutive ticks).
std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q, const KeyPoseBlend& blend = {});

/// As above, with the segments taken from the measured samples (t_s, q) and the trajectory
/// evaluated on the tick grid t_eval (increasing; e.g. the whole 10 Hz grid, including samples
/// where no human was measured, which keep the key pose of the last measured sample): one output
/// pose per entry of t_eval. Throws InputError for mismatched lengths, no measured sample or a
/// decreasing grid.
std::vector<JointVector> featureTrajectory(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                                           const std::vector<JointVector>& q, const std::vector<double>& t_eval,
                                           const KeyPoseBlend& blend = {});

/// The key pose in force at each tick of t_eval (index into centroids), by the rule above.
std::vector<int> keyPoseLabels(const std::vector<JointVector>& centroids, const std::vector<double>& t_s,
                               const std::vector<JointVector>& q, const std::vector<double>& t_eval);

}  // namespace nao
