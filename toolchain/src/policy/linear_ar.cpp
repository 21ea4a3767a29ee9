#include "nao/tools/linear_ar.hpp"
#include "nao/sim_arm.hpp"

#include "nao/kinematics.hpp"
#include "nao/robot_backend.hpp"
#include "nao/rollout.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <stdexcept>
#include <string>

namespace nao::tools {
namespace {

// Angle and action of sample t of a trajectory, with the arm at rest at f(0) before t = 0.
double angleAt(const std::vector<JointVector>& f, int joint, long t) {
  return f[static_cast<std::size_t>(std::max(0L, t))][joint];
}
double actionAt(const std::vector<JointVector>& f, int joint, long t) {
  if (t < 0) return 0.0;
  const auto i = static_cast<std::size_t>(t);
  return f[i + 1][joint] - f[i][joint];
}

std::size_t countSamples(const std::vector<std::vector<JointVector>>& trajectories) {
  std::size_t n = 0;
  for (const auto& f : trajectories)
    if (f.size() >= 2) n += f.size() - 1;
  return n;
}

// Regressors of sample t: [1, q(t), a(t−1), ..., a(t−order)].
void regressors(const std::vector<JointVector>& f, int joint, long t, int order, double* x) {
  x[0] = 1.0;
  x[1] = angleAt(f, joint, t);
  for (int k = 1; k <= order; ++k) x[1 + k] = actionAt(f, joint, t - k);
}

double predict(const LinearArJoint& m, double q, const double* a_past) {
  double a = m.c + m.beta * q;
  for (int k = 1; k <= m.order; ++k) a += m.alpha[static_cast<std::size_t>(k - 1)] * a_past[k - 1];
  return a;
}

}  // namespace

LinearArJoint fitLinearArJoint(const std::vector<std::vector<JointVector>>& trajectories, int joint, int order) {
  if (order < 1 || order > kMaxLinearArOrder)
    throw std::invalid_argument("linear AR order " + std::to_string(order) + " outside 1.." +
                                std::to_string(kMaxLinearArOrder));
  const int cols = order + 2;
  const std::size_t n = countSamples(trajectories);
  if (n < static_cast<std::size_t>(cols))
    throw std::invalid_argument("linear AR of order " + std::to_string(order) + ": " + std::to_string(n) +
                                " samples for " + std::to_string(cols) + " unknowns");
  Eigen::MatrixXd X(static_cast<Eigen::Index>(n), cols);
  Eigen::VectorXd y(static_cast<Eigen::Index>(n));
  Eigen::Index row = 0;
  std::vector<double> x(static_cast<std::size_t>(cols));
  for (const auto& f : trajectories) {
    for (long t = 0; t + 1 < static_cast<long>(f.size()); ++t) {
      regressors(f, joint, t, order, x.data());
      for (int c = 0; c < cols; ++c) X(row, c) = x[static_cast<std::size_t>(c)];
      y(row) = actionAt(f, joint, t);
      ++row;
    }
  }
  const Eigen::VectorXd w = X.colPivHouseholderQr().solve(y);
  LinearArJoint m;
  m.order = order;
  m.c = w(0);
  m.beta = w(1);
  for (int k = 1; k <= order; ++k) m.alpha.push_back(w(1 + k));
  m.train_mse = linearArMse(m, trajectories, joint);
  return m;
}

double linearArMse(const LinearArJoint& m, const std::vector<std::vector<JointVector>>& trajectories, int joint) {
  double sum = 0.0;
  std::size_t n = 0;
  std::vector<double> a_past(static_cast<std::size_t>(std::max(1, m.order)));
  for (const auto& f : trajectories) {
    for (long t = 0; t + 1 < static_cast<long>(f.size()); ++t) {
      for (int k = 1; k <= m.order; ++k) a_past[static_cast<std::size_t>(k - 1)] = actionAt(f, joint, t - k);
      const double e = predict(m, angleAt(f, joint, t), a_past.data()) - actionAt(f, joint, t);
      sum += e * e;
      ++n;
    }
  }
  return n > 0 ? sum / static_cast<double>(n) : 0.0;
}

LinearArModel fitLinearAr(const std::vector<std::vector<JointVector>>& train,
                          const std::vector<std::vector<JointVector>>& val, int max_order) {
  if (max_order < 1 || max_order > kMaxLinearArOrder)
    throw std::invalid_argument("linear AR: maximum order " + std::to_string(max_order) + " outside 1.." +
                                std::to_string(kMaxLinearArOrder));
  LinearArModel model;
  for (int j = 0; j < kNumJoints; ++j) {
    std::vector<LinearArJoint> fits;
    std::vector<double> mse;
    for (int p = 1; p <= max_order; ++p) {
      fits.push_back(fitLinearArJoint(train, j, p));
      mse.push_back(linearArMse(fits.back(), val, j));
    }
    const double best = *std::min_element(mse.begin(), mse.end());
    std::size_t pick = 0;
    while (!(mse[pick] <= best * (1.0 + 1e-9) + 1e-24)) ++pick;
    LinearArJoint m = fits[pick];
    m.val_mse_by_order = mse;
    model.joints[static_cast<std::size_t>(j)] = m;
  }
  return model;
}

JointVector linearArAction(const LinearArModel& m, const JointVector& q, const std::vector<JointVector>& a_past) {
  JointVector a;
  for (int j = 0; j < kNumJoints; ++j) {
    const LinearArJoint& mj = m.joints[static_cast<std::size_t>(j)];
    double v = mj.c + mj.beta * q[j];
    for (int k = 1; k <= mj.order && static_cast<std::size_t>(k) <= a_past.size(); ++k)
      v += mj.alpha[static_cast<std::size_t>(k - 1)] * a_past[static_cast<std::size_t>(k - 1)][j];
    a[j] = v;
  }
  return a;
}

Rollout rolloutOn(const ArmModel& arm, RobotBackend& robot, double period_s, const JointVector& q0, int ticks,
                  const ActionLaw& law) {
  Rollout r;
  ArmData kin;
  const JointVector start = clampToLimits(arm, q0);
  robot.activate(start);
  r.hand.push_back(forwardKinematics(arm, kin, start));
  std::vector<JointVector> a_past;  // newest first
  CommandStep step;
  for (int t = 0; t < ticks; ++t) {
    const JointVector a = law(robot.measured(), a_past);
    r.q.push_back(rolloutStep(arm, period_s, robot, a, step));
    if (step.limit & kCommandClamped) ++r.limited_ticks;
    r.a_applied.push_back(step.a_applied);
    a_past.insert(a_past.begin(), step.a_applied);
    if (a_past.size() > static_cast<std::size_t>(kMaxLinearArOrder)) a_past.pop_back();
    r.hand.push_back(forwardKinematics(arm, kin, r.q.back()));
  }
  return r;
}

Rollout rolloutOnSim(const SimModel& sim, SimData& data, double period_s, const JointVector& q0, int ticks,
                     const ActionLaw& law) {
  OdeArmBackend robot(sim, data);
  return rolloutOn(sim.arm, robot, period_s, q0, ticks, law);
}

}  // namespace nao::tools
