// The linear autoregressive baseline of the autonomous mode: per movement
// and joint, the action a_j(t) = f_j(t+1) − f_j(t) of the feature-extracted trajectory f
// predicted by least squares from the joint's own angle and its past actions,
//
//   a_j(t) = c_j + β_j q_j(t) + Σ_{k=1..p_j} α_jk a_j(t−k),
//
// and rolled out the way nao_rt rolls out the policy: from a start pose s_0 through the
// simulated ODE arm, the command limited as controller.hpp step 4 limits it, the applied
// action fed back as the next a(t−1). Offline code: allocates, may throw.
//
// Why q_j(t) and no older angles: on a trajectory q_j(t−k) = q_j(t) − Σ_{i=1..k} a_j(t−i)
// exactly, so older angles are linear combinations of the regressors already there and their
// coefficients cannot be told apart by the training data (the design matrix would be singular).
// Before t = 0 the arm is taken at rest at f(0) (a = 0), the state a rollout starts from.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/robot_backend.hpp"  // rolloutStep: the command rule every rollout here follows
#include "nao/sim_arm.hpp"

#include <Eigen/Core>

#include <array>
#include <functional>
#include <vector>

namespace nao::tools {

inline constexpr int kMaxLinearArOrder = 12;

/// One joint's fitted model: a = c + beta q + Σ alpha[k−1] a(t−k), k = 1..order.
struct LinearArJoint {
  int order = 1;
  double c = 0.0;
  double beta = 0.0;
  std::vector<double> alpha;  ///< order entries
  std::vector<double> val_mse_by_order;  ///< one-step validation MSE (rad²) for orders 1..max (selection)
  double train_mse = 0.0;                ///< one-step MSE on the training trajectories at `order`, rad²
};

/// The five joints' models of one movement.
struct LinearArModel {
  std::array<LinearArJoint, kNumJoints> joints;
};

/// Fits joint `joint`'s model of order `order` (1..kMaxLinearArOrder) to the trajectories by
/// least squares (column-pivoted QR). Every sample t = 0 .. n−2 of every trajectory is one
/// equation. Throws std::invalid_argument for an order out of range or fewer equations than
/// unknowns.
LinearArJoint fitLinearArJoint(const std::vector<std::vector<JointVector>>& trajectories, int joint, int order);

/// One-step mean squared error (rad²) of `m` on the trajectories' samples.
double linearArMse(const LinearArJoint& m, const std::vector<std::vector<JointVector>>& trajectories, int joint);

/// Per joint, fits every order 1..max_order on `train` and keeps the one with the lowest
/// one-step MSE on `val` (ties, within a relative 1e-9 plus 1e-24 rad², go to the lower order).
LinearArModel fitLinearAr(const std::vector<std::vector<JointVector>>& train,
                          const std::vector<std::vector<JointVector>>& val, int max_order);

/// The action of `m` given the joint angles q(t) and the past applied actions, newest first
/// (a_past[0] = a(t−1); entries beyond its size count as 0).
JointVector linearArAction(const LinearArModel& m, const JointVector& q, const std::vector<JointVector>& a_past);

/// A rollout's record: the hand path (the start pose's hand point, then one per tick), joint
/// angles after each tick, and the ticks whose command was limited.
struct Rollout {
  std::vector<Eigen::Vector3d> hand;  ///< torso frame, m; ticks + 1 points
  std::vector<JointVector> q;         ///< ticks entries
  std::vector<JointVector> a_applied; ///< ticks entries: the action as the limiter let it through (q_cmd − q)
  int limited_ticks = 0;
};

/// The action law of a rollout: (q(t), past applied actions newest first) -> a(t).
using ActionLaw = std::function<JointVector(const JointVector&, const std::vector<JointVector>&)>;

/// Rolls `law` out for `ticks` ticks on the simulated arm from rest at q0 (clamped to the
/// limits) with the runtime's own rollout step (rolloutStep: measured q -> action -> the
/// controller's command, commandFor -> one period of the arm, a non-finite action held); the applied action
/// (command − q) is the next tick's a(t−1). `data` is reused (reset to q0).
Rollout rolloutOnSim(const SimModel& sim, SimData& data, double period_s, const JointVector& q0, int ticks,
                     const ActionLaw& law);

/// The same on any robot backend of `arm` (the ODE arm, or the trainer's copy of it,
/// nao/tools/arm_copy.hpp), activated at q0 clamped to the limits.
Rollout rolloutOn(const ArmModel& arm, RobotBackend& robot, double period_s, const JointVector& q0, int ticks,
                  const ActionLaw& law);

}  // namespace nao::tools
