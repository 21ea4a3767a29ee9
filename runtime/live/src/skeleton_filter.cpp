#include "nao/skeleton_filter.hpp"

#include <cmath>

namespace nao {
namespace {

constexpr double kTwoPi = 2.0 * 3.14159265358979323846;

// Smoothing factor of a first-order low-pass with cutoff fc (Hz) over dt (s).
double smoothingFactor(double cutoff_hz, double dt_s) {
  const double tau = 1.0 / (kTwoPi * cutoff_hz);
  return 1.0 / (1.0 + tau / dt_s);
}

}  // namespace

void resetSkeletonLowPass(SkeletonLowPass& state) noexcept {
  state.p_W.fill(Eigen::Vector3d::Zero());
  state.v_W.fill(Eigen::Vector3d::Zero());
  state.t_s.fill(0.0);
  state.started.fill(false);
}

void lowPassSkeleton(const SkeletonLowPassParams& params, SkeletonLowPass& state, SkeletonFrame& frame) noexcept {
  if (!(params.min_cutoff_hz > 0.0)) return;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    if (!frame.ok[i] || frame.interpolated[i]) continue;
    const double dt = frame.t_s - state.t_s[i];
    if (!state.started[i] || !(dt > 0.0) || dt > params.reset_after_s) {
      state.p_W[i] = frame.p_W[i];
      state.v_W[i].setZero();
    } else {
      const Eigen::Vector3d v_raw = (frame.p_W[i] - state.p_W[i]) / dt;
      state.v_W[i] += smoothingFactor(params.derivative_cutoff_hz, dt) * (v_raw - state.v_W[i]);
      const double cutoff = params.min_cutoff_hz + params.beta_s_per_m * state.v_W[i].norm();
      state.p_W[i] += smoothingFactor(cutoff, dt) * (frame.p_W[i] - state.p_W[i]);
    }
    state.started[i] = true;
    state.t_s[i] = frame.t_s;
    frame.p_W[i] = state.p_W[i];
  }
}

}  // namespace nao
