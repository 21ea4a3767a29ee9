// Causal low-pass of a live 3D skeleton: the One Euro filter (Casiez, Roussel, Vogel, "1 Euro
// filter: a simple speed-based low-pass filter for noisy input in interactive systems", CHI
// 2012), per point on its 3D position. A first-order low-pass whose cutoff rises with the
// point's speed: min_cutoff_hz when it rests (triangulation noise is smoothed away), more when
// it moves (little lag where lag would hurt). Variable frame intervals are fine (the smoothing
// factor follows each dt). A point measured again after more than reset_after_s starts afresh.
// Real-time safe (fixed-size state, no allocation); used on the live camera's reader thread.
#pragma once

#include "nao/body25.hpp"

#include <Eigen/Core>

#include <array>

namespace nao {

struct SkeletonLowPassParams {
  double min_cutoff_hz = 0.0;         ///< cutoff at rest, Hz; 0: the filter is off
  double beta_s_per_m = 0.0;          ///< cutoff increase per m/s of speed, Hz / (m/s)
  double derivative_cutoff_hz = 1.0;  ///< low-pass of the speed estimate, Hz
  double reset_after_s = 0.2;         ///< a point unmeasured longer starts afresh
};

struct SkeletonLowPass {
  std::array<Eigen::Vector3d, kNumSkeletonPoints> p_W;    ///< filtered position, m
  std::array<Eigen::Vector3d, kNumSkeletonPoints> v_W;    ///< filtered velocity, m/s
  std::array<double, kNumSkeletonPoints> t_s{};           ///< time of the last measurement, s
  std::array<bool, kNumSkeletonPoints> started{};
};

/// Forgets every point. Real-time safe.
void resetSkeletonLowPass(SkeletonLowPass& state) noexcept;

/// Filters the measured points of `frame` (ok and not interpolated) in place at time
/// frame.t_s, which must be later than the previous call's. Others are left alone. Nothing
/// happens when params.min_cutoff_hz <= 0. Real-time safe.
void lowPassSkeleton(const SkeletonLowPassParams& params, SkeletonLowPass& state, SkeletonFrame& frame) noexcept;

}  // namespace nao
