// The policy's training data (docs/policy.md "Data"): a clustered data set (centroids.json +
// <movement>_<index>/features.csv from `nao_toolchain cluster`), its demonstrations executed on
// the simulated arm (policy_execution.cpp), the seeded train/validation split by demonstration,
// the normalisation statistics of the training split, the one-step baselines and the data
// fingerprint.
// Offline code without libtorch: allocates and may throw (UserError for bad input).
#pragma once

#include "nao/model_file.hpp"
#include "nao/rollout.hpp"

#include "nao/arm_model.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/kmeans.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace nao::tools {

/// One demonstration's feature-extracted trajectory on its 10 Hz grid (one entry per row of
/// features.csv).
struct PolicyDemo {
  std::string name;                    ///< "<movement>_<index>", the folder name
  int movement = 0;                    ///< index into PolicyData::movement_names (set by makePolicyData)
  std::vector<double> t_s;             ///< sample times, s (strictly increasing)
  std::vector<int> label;              ///< nearest centroid of each sample, 0..K-1
  std::vector<std::uint8_t> measured;  ///< 1: a human arm was measured at the sample, 0: held
  std::vector<JointVector> f;          ///< feature-extracted joint trajectory, rad
  /// The start state of an autonomous run of this demonstration: the retargeted reference q_r at
  /// its first measured sample (the demonstrator's own first pose, not a key pose), rad;
  /// f(0) when the data set has no retarget.csv beside features.csv. NaN (unset): makePolicyData
  /// takes f(0).
  JointVector start = JointVector::Constant(std::numeric_limits<double>::quiet_NaN());
};

/// A whole data set in memory. Built by loadPolicyData or makePolicyData, which validate it.
struct PolicyData {
  std::vector<std::string> movement_names;          ///< sorted; index = movement index m
  std::vector<std::vector<JointVector>> centroids;  ///< [movement][cluster], rad; K per movement
  std::vector<PolicyDemo> demos;                    ///< sorted by name
  /// The retargeting setting of the clustered reference (centroids.json "retarget": priority,
  /// lambda_q, posture_weights) as JSON; empty when the data set does not say.
  std::string retarget_json;

  int movements() const { return static_cast<int>(movement_names.size()); }
  int clusters() const { return centroids.empty() ? 0 : static_cast<int>(centroids.front().size()); }
};

/// Per-joint normalisation statistics (population standard deviation, floored at kMinStd).
struct NormStats {
  JointVector q_mean, q_std;  ///< over q(t)
  JointVector a_mean, a_std;  ///< over the target actions a(t) (also used for a(t-1))
  JointVector r_mean, r_std;  ///< over r(t)
};
inline constexpr double kMinStd = 1e-6;  ///< rad

/// Demonstrations of the training and validation split (indices into PolicyData::demos,
/// ascending). No demonstration is in both.
struct PolicySplit {
  std::vector<int> train;
  std::vector<int> val;
};

/// One-step MSE over ticks and joints (rad^2) of the closed-form predictors of a(t) a learned
/// policy is measured against.
struct Baselines {
  double zero_action = 0.0;  ///< predict a(t) = 0
  double repeat_last = 0.0;  ///< predict a(t) = a(t-1)
  /// predict a(t) = g r(t), g = 1 / (1 − exp(−K T)): the first-order servo inversion of the
  /// tick's target (r = f(t+1) − q(t)), the law reference mode adds (docs/policy.md)
  double gain_law = 0.0;
};

/// Reads DIR/centroids.json and every DIR/<movement>_<index>/features.csv (columns t_s, label,
/// optional measured (missing: all 1), f_0..f_4), and each demonstration's start from
/// retarget.csv beside it (qr_0..qr_4 at the first measured sample's t_s; without the file,
/// f(0)), then makePolicyData. Throws UserError naming the file (and line) for a missing or
/// malformed directory, file or value.
PolicyData loadPolicyData(const std::string& dir);

/// `data` with every demonstration's f restarted from rest at its start: the key-pose blend
/// (KeyPoseBlend, the data's pole) over the same key poses in force (label), from f(0) = start
/// instead of the first key pose. An autonomous run starts where its demonstrator did; after a
/// few ticks the trajectory is f again (docs/policy.md "Data").
PolicyData fromOwnStarts(const PolicyData& data);

/// Per movement (data.movement_names order), the joint range its demonstrations cover (their
/// feature trajectories and their starts), rad: the "workspace" an autonomous model carries
/// (modelWorkspace).
std::vector<ModelWorkspace> demonstratedWorkspace(const PolicyData& data);

/// Builds a data set from memory: the movements are the keys of `centroids` (sorted, so the
/// movement index is the position in name order), each demo's movement is the part of its name
/// before the last '_', demos are sorted by name. Throws UserError for inconsistent input:
/// unequal or zero K, a demo name that is not <movement>_<index> or names a movement without
/// centroids, a duplicate demo name, fewer than 2 samples, unequal column lengths,
/// non-increasing times, a label outside 0..K-1, a measured flag other than 0/1, a
/// non-finite value.
PolicyData makePolicyData(const std::map<std::string, std::vector<JointVector>>& centroids,
                          std::vector<PolicyDemo> demos);

/// How the training rollouts are executed (docs/policy.md
/// "Data"). Each demonstration's feature-extracted trajectory f is followed by the simulated,
/// servo-lagged ODE arm (nao::SimModel, the arm nao_rt drives) under the *expert*: at every tick
/// the command c(t) for which the arm, from its present dynamic state, ends the tick at f(t+1)
/// (found by secant iterations on a snapshot of the simulation, within the controller's
/// position and per-tick velocity bounds). The label is a(t) = c(t) − q(t), the policy's action
/// as the controller applies it. Besides one clean rollout per demonstration, `noisy_rollouts`
/// more execute c(t) + n(t) with AR(1) command noise n (DART: the states off the trajectory the
/// policy's own errors reach, labelled by the expert from there); the inputs are what the
/// controller sees (measured q, the applied a(t−1), and as r the offset f(t+1) − q(t) of the
/// feature-extracted target the controller computes online from the snapped key poses). Every
/// rollout's expert aims at f(t+1), the demonstration's pose of the same tick: a noisy state
/// that fell behind or aside is asked to catch up in one tick.
struct ExecutionOptions {
  int noisy_rollouts = 1;                          ///< per demonstration, besides the clean one
  double noise_corr = 0.8;                         ///< ρ of the AR(1) noise, per tick
  int expert_iterations = 8;                       ///< secant steps per tick (iteration cap)
  double expert_tol_rad = 1e-7;                    ///< stop when every joint ends this close to f(t+1)
  /// Noisy rollouts start from rest at another training demonstration's start of the same
  /// movement (a seeded choice among the listed ones) instead of their own: the states on the
  /// way from a start onto the demonstration. The result then depends on the listed demos.
  bool other_starts = false;
  /// Worker threads (the result does not depend on it). 1: Debian's ODE 0.16 crashed (segfault
  /// in libode) with two worlds stepped on two threads here; more only with an ODE built for it.
  int threads = 1;
};

/// σ of the noisy rollouts' stationary AR(1) command noise, rad: noisy rollout k takes entry
/// (k − 1) % 2.
inline constexpr std::array<double, 2> kNoiseStdRad = {0.03, 0.06};

/// One executed rollout of a demonstration: T − 1 ticks (every sample with a successor), rad.
struct PolicySequence {
  int demo = 0;      ///< index into PolicyData::demos
  int movement = 0;
  int rollout = 0;   ///< 0: clean, k >= 1: noisy rollout k
  std::vector<JointVector> q;       ///< measured q(t) at the start of tick t (q(0) = f(0), at rest)
  std::vector<JointVector> a_prev;  ///< a(t−1) as applied (c(t−1) − q(t−1)), 0 at t = 0
  std::vector<JointVector> r;       ///< reference input: f(t+1) − q(t), f(t+1) the tick's feature-extracted target (clamped)
  std::vector<JointVector> a;       ///< label: the expert's c(t) − q(t)
  double worst_miss_rad = 0.0;      ///< largest |q(t+1) − f(t+1)| of the expert's command (clean rollout)
  std::size_t ticks() const { return a.size(); }
};

/// Executes the listed demonstrations (clean + noisy rollouts each, in list order) on the
/// simulated arm of `sim_model` with the controller's per-tick bounds (period = the model's
/// substeps × dt), from rest at each f(0). Seeded: the noise of (demo, rollout) comes from its
/// own splitmix64 stream, so the result does not depend on which other demos are listed or on
/// options.threads. Deterministic (ODE's direct solver). Prints a progress line per 10 % to
/// `progress` if not null. Throws UserError for bad options.
std::vector<PolicySequence> executeDemos(const PolicyData& data, const std::vector<int>& demos,
                                         const SimModel& sim_model, const ExecutionOptions& options,
                                         std::uint64_t seed, std::ostream* progress = nullptr);

/// A policy for rolloutPolicy: the action a(t), rad, before the controller's limits, from the
/// inputs the controller gives it (measured q(t), the applied a(t−1), r = f(t+1) − q(t)) at tick
/// t of a run of `movement`. t == 0 starts a new run (a streaming policy resets its window).
using RolloutPolicy = std::function<JointVector(int movement, int t, const JointVector& q, const JointVector& a_prev,
                                                const JointVector& r)>;

/// A policy's run from a demonstration's start.
struct PolicyRun {
  int demo = 0;
  int movement = 0;
  std::vector<JointVector> q;  ///< q(0) = the start, then the measured q after each tick: f's length
  std::vector<JointVector> a;  ///< the policy's action of each tick, before the limits
};

/// Each listed demonstration's run on the simulated arm: from rest at its f(0) (its start:
/// fromOwnStarts), the policy's action applied as the controller applies it (q + a inside the
/// position limits and v_max·period; a non-finite action is 0; the applied action is the next
/// a(t−1)), for as many ticks as f has successors. r is the demonstration's clamped f(t+1) − q
/// (what a reference-mode policy sees). `workspace` (per movement; nullptr: none) keeps the
/// commands in an autonomous model's workspace envelope, as the controller does. Deterministic
/// for a deterministic policy; one thread, in list order (the policy may be stateful). Throws
/// UserError for an index out of range.
std::vector<PolicyRun> rolloutPolicy(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim_model,
                                     const RolloutPolicy& policy, const std::vector<JointEnvelope>* workspace = nullptr);

/// Normalisation statistics over every tick of `sequences` (q, the labels a, r). Throws UserError
/// when there is no tick.
NormStats normStats(const std::vector<PolicySequence>& sequences);

/// The baselines' one-step MSE over every tick of `sequences`, rad^2; `gain` is the gain law's g.
Baselines baselines(const std::vector<PolicySequence>& sequences, double gain);

/// Ticks in all sequences.
std::size_t tickCount(const std::vector<PolicySequence>& sequences);

/// Seeded split by demonstration: per movement, its demos (in name order) are shuffled
/// (Fisher-Yates with a local splitmix64 generator; one stream per movement derived from
/// `seed`), and the last round(val_fraction * n) become validation, at least 1 when n >= 2 and
/// val_fraction > 0, and at most n - 1. Throws UserError unless 0 <= val_fraction < 1.
PolicySplit splitByDemonstration(const PolicyData& data, double val_fraction, std::uint64_t seed);

/// 0..n-1 in a seeded random order (Fisher-Yates with a local splitmix64 generator): the same
/// on every platform and standard library.
std::vector<std::size_t> shuffledIndices(std::size_t n, std::uint64_t seed);

/// FNV-1a 64 over the data set in a canonical little-endian byte form: movement names and
/// centroids, then per demo (name order) its name, movement, start, and per sample t_s, label,
/// measured, f (f64). Equal data give equal fingerprints on every platform.
std::uint64_t dataFingerprint(const PolicyData& data);

/// 16 lower-case hex digits.
std::string hex64(std::uint64_t value);

/// Names of the listed demonstrations.
std::vector<std::string> demoNames(const PolicyData& data, const std::vector<int>& demos);

}  // namespace nao::tools
