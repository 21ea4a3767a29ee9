#include "arm_copy_torch.hpp"

#include "nao/kinematics.hpp"
#include "nao/rollout.hpp"
#include "nao/tools/arm_copy.hpp"

#include <stdexcept>

namespace nao::tools {
namespace {

using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

JointVector row(const torch::TensorAccessor<double, 1>& t) {
  JointVector v;
  for (int j = 0; j < kNumJoints; ++j) v[j] = t[j];
  return v;
}

// Saved for backward, per run b and joint j: the copy's Jacobian jac[b][j] (2×3), the limiter's
// (∂c/∂q, ∂c/∂a) lim[b][j], and the hand Jacobian hand_jac[b] (3×J).
struct ArmCopyTickFn : torch::autograd::Function<ArmCopyTickFn> {
  static variable_list forward(AutogradContext* ctx, const torch::Tensor& q_in, const torch::Tensor& v_in,
                               const torch::Tensor& a_in, const SimModel* sim, double period_s,
                               const torch::Tensor& env_lo, const torch::Tensor& env_hi) {
    const torch::Tensor q = q_in.detach().to(torch::kFloat64).contiguous();
    const torch::Tensor v = v_in.detach().to(torch::kFloat64).contiguous();
    const torch::Tensor a = a_in.detach().to(torch::kFloat64).contiguous();
    const torch::Tensor lo = env_lo.to(torch::kFloat64).contiguous(), hi = env_hi.to(torch::kFloat64).contiguous();
    const std::int64_t n = q.size(0);
    torch::Tensor q_out = torch::empty({n, kNumJoints}, torch::kFloat64), v_out = torch::empty_like(q_out);
    torch::Tensor applied = torch::empty_like(q_out), hand = torch::empty({n, 3}, torch::kFloat64);
    torch::Tensor jac = torch::empty({n, kNumJoints, 2, 3}, torch::kFloat64);
    torch::Tensor lim = torch::empty({n, kNumJoints, 2}, torch::kFloat64);
    torch::Tensor hand_jac = torch::empty({n, 3, kNumJoints}, torch::kFloat64);
    auto qa = q.accessor<double, 2>(), va = v.accessor<double, 2>(), aa = a.accessor<double, 2>();
    auto loa = lo.accessor<double, 2>(), hia = hi.accessor<double, 2>();
    auto qo = q_out.accessor<double, 2>(), vo = v_out.accessor<double, 2>(), ap = applied.accessor<double, 2>();
    auto ho = hand.accessor<double, 2>();
    auto ja = jac.accessor<double, 4>();
    auto la = lim.accessor<double, 3>();
    auto hj = hand_jac.accessor<double, 3>();
    ArmData kin;
    for (std::int64_t b = 0; b < n; ++b) {
      ArmCopyState s;
      s.q = row(qa[b]);
      s.v = row(va[b]);
      const JointVector act = row(aa[b]);
      JointEnvelope env;
      env.lo = row(loa[b]);
      env.hi = row(hia[b]);
      JointVector q_cmd;
      limitCommand(sim->arm, period_s, s.q, act, q_cmd, &env);
      const CommandDerivative dc = commandDerivative(sim->arm, period_s, s.q, act, q_cmd);
      ArmCopyJacobian J;
      const JointVector q0 = s.q;
      stepArmCopy(*sim, s, q_cmd, &J);
      forwardKinematics(sim->arm, kin, s.q);
      handJacobian(sim->arm, kin);
      for (int j = 0; j < kNumJoints; ++j) {
        qo[b][j] = s.q[j];
        vo[b][j] = s.v[j];
        ap[b][j] = q_cmd[j] - q0[j];
        la[b][j][0] = dc.d_q[j];
        la[b][j][1] = dc.d_a[j];
        for (int r = 0; r < 2; ++r)
          for (int c = 0; c < 3; ++c) ja[b][j][r][c] = J.d[static_cast<std::size_t>(j)](r, c);
        for (int r = 0; r < 3; ++r) hj[b][r][j] = kin.Jp_TH(r, j);
      }
      for (int r = 0; r < 3; ++r) ho[b][r] = kin.p_TH[r];
    }
    ctx->save_for_backward({jac, lim, hand_jac});
    return {q_out, v_out, applied, hand};
  }

  static variable_list backward(AutogradContext* ctx, variable_list grad) {
    const variable_list saved = ctx->get_saved_variables();
    const torch::Tensor &jac = saved[0], &lim = saved[1], &hand_jac = saved[2];
    // The end angles feed both q' and the hand point.
    const torch::Tensor g_q1 = grad[0] + grad[3].unsqueeze(1).matmul(hand_jac).squeeze(1);  // [B,J]
    const torch::Tensor g_v1 = grad[1];
    const torch::Tensor g_applied = grad[2];
    // (g_q0, g_v0, g_c) = [g_q1, g_v1] · ∂(q1, v1)/∂(q0, v0, c), joint by joint.
    const torch::Tensor g_state = torch::stack({g_q1, g_v1}, -1).unsqueeze(-2).matmul(jac).squeeze(-2);  // [B,J,3]
    // a_applied = c − q.
    const torch::Tensor g_c = g_state.select(2, 2) + g_applied;
    const torch::Tensor g_q = g_state.select(2, 0) - g_applied + g_c * lim.select(2, 0);
    const torch::Tensor g_a = g_c * lim.select(2, 1);
    return {g_q, g_state.select(2, 1), g_a, torch::Tensor(), torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

ArmTick armCopyTick(const SimModel& sim, double period_s, const torch::Tensor& q, const torch::Tensor& v,
                    const torch::Tensor& a, const torch::Tensor& env_lo, const torch::Tensor& env_hi) {
  if (q.dim() != 2 || q.size(1) != kNumJoints || v.sizes() != q.sizes() || a.sizes() != q.sizes() ||
      env_lo.sizes() != q.sizes() || env_hi.sizes() != q.sizes())
    throw std::invalid_argument("armCopyTick: q, v, a and the envelope must all be [B," + std::to_string(kNumJoints) + "]");
  const variable_list out = ArmCopyTickFn::apply(q, v, a, &sim, period_s, env_lo, env_hi);
  return {out[0], out[1], out[2], out[3]};
}

}  // namespace nao::tools
