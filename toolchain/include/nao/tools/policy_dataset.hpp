// The policy's training data (docs/policy.md "Data"): a clustered data set (centroids.json +
// <movement>_<index>/features.csv from `nao_toolchain cluster`), the samples built from it,
// the seeded train/validation split by demonstration, the normalisation statistics of the
// training split, the zero-action and repeat-last-action baselines and the data fingerprint.
// Offline code without libtorch: allocates and may throw (UserError for bad input).
#pragma once

#include "nao/arm_model.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/kmeans.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <map>
#include <optional>
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

/// One training sample (docs/policy.md "Data"), rad.
struct PolicySample {
  JointVector q;       ///< q(t) = f(t)
  JointVector a_prev;  ///< a(t-1) = f(t) - f(t-1), 0 at t = 0
  JointVector r;       ///< r(t) = centroid label(t) of the demonstration's movement
  JointVector a;       ///< target a(t) = f(t+1) - f(t)
  int movement = 0;    ///< m
  int step = 0;        ///< s = t, clamped to max_steps - 1
  int demo = 0;        ///< index into PolicyData::demos
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

/// MSE over samples and joints (rad^2) of two trivial predictors of a(t).
struct Baselines {
  double zero_action = 0.0;  ///< predict a(t) = 0
  double repeat_last = 0.0;  ///< predict a(t) = a(t-1)
};

/// Reads DIR/centroids.json and every DIR/<movement>_<index>/features.csv (columns t_s, label,
/// optional measured (missing: all 1), f_0..f_4), then makePolicyData. Throws UserError naming
/// the file (and line) for a missing or malformed directory, file or value.
PolicyData loadPolicyData(const std::string& dir);

/// Builds a data set from memory: the movements are the keys of `centroids` (sorted, so the
/// movement index is the position in name order), each demo's movement is the part of its name
/// before the last '_', demos are sorted by name. Throws UserError for inconsistent input:
/// unequal or zero K, a demo name that is not <movement>_<index> or names a movement without
/// centroids, a duplicate demo name, fewer than 2 samples, unequal column lengths,
/// non-increasing times, a label outside 0..K-1, a measured flag other than 0/1, a
/// non-finite value.
PolicyData makePolicyData(const std::map<std::string, std::vector<JointVector>>& centroids,
                          std::vector<PolicyDemo> demos);

/// The samples of demonstration `demo` (one per sample with a successor), steps clamped to
/// max_steps - 1.
std::vector<PolicySample> buildSamples(const PolicyData& data, int demo, int max_steps);

/// The samples of the listed demonstrations, concatenated in list order.
std::vector<PolicySample> buildSamples(const PolicyData& data, const std::vector<int>& demos, int max_steps);

/// How the training rollouts are executed (DESIGN §7, "execution dynamics"; docs/policy.md
/// "Data"). Each demonstration's feature-extracted trajectory f is followed by the simulated,
/// servo-lagged ODE arm (nao::SimModel, the arm nao_rt drives) under the *expert*: at every tick
/// the command c(t) for which the arm, from its present dynamic state, ends the tick at f(t+1)
/// (found by secant iterations on a snapshot of the simulation, within the controller's
/// position and per-tick velocity bounds). The label is a(t) = c(t) − q(t), the policy's action
/// as the controller applies it. Besides one clean rollout per demonstration, `noisy_rollouts`
/// more execute c(t) + n(t) with AR(1) command noise n (DART: the states off the trajectory the
/// policy's own errors reach, labelled by the expert from there); the inputs are what the
/// controller sees (measured q, the applied a(t−1), and as r the offset f(t+1) − q(t) of the
/// feature-extracted target the controller computes online from the snapped key poses).
struct ExecutionOptions {
  int noisy_rollouts = 1;                          ///< per demonstration, besides the clean one
  std::vector<double> noise_std_rad = {0.03, 0.06};  ///< σ of noisy rollout k: entry (k − 1) % size
  double noise_corr = 0.8;                         ///< ρ of the AR(1) noise, per tick
  int expert_iterations = 8;                       ///< secant steps per tick (iteration cap)
  double expert_tol_rad = 1e-7;                    ///< stop when every joint ends this close to f(t+1)
  /// DAgger's β (Ross et al. 2011): in the policy's rollout of round i >= 1 each tick executes
  /// the expert's command instead of the policy's with probability dagger_beta^i (seeded per
  /// demonstration and round); 0 is the pure policy. Round 0 (rollout scoring) is always pure.
  double dagger_beta = 0.0;
  /// DAgger: a round's rollout ends before the first tick whose drift |q(t) − f(t)| (clamped f,
  /// any joint) exceeds this, rad: the states past it are left out (measured in docs/policy.md:
  /// the labels of the states kept still did not help). 0: no bound. Round 0 (scoring) is never cut.
  double dagger_max_drift_rad = 0.0;
  /// DAgger labels from a time-aligned point instead of the clock's (docs/policy.md "Data").
  /// 0: the expert's target is the rollout's demonstration at f(t+1) (the clock), as for the
  /// executed demonstrations. > 0: the point (d, k) of the alignment pool's demonstrations of
  /// the movement nearest the arm's state (position and per-tick velocity) with |k − t| <= this
  /// many ticks is found, and the label comes from it (dagger_align_label); the drift bound then
  /// measures the distance to that point. Round 0 (scoring) labels nothing.
  int dagger_align_band = 0;
  /// What an aligned label is. kSuccessor: the expert's command (secant) that ends the tick at
  /// f_d(k+1) + (1 − γ)(q − f_d(k)), γ = dagger_return. kCommand: the command the expert gave
  /// at (d, k) in d's clean execution, inside the controller's bounds at q (no secant: the
  /// servo itself takes the arm back, at its own pace).
  enum class AlignLabel { kSuccessor, kCommand };
  AlignLabel dagger_align_label = AlignLabel::kSuccessor;
  /// kSuccessor: the share γ of the offset q − f_d(k) the label takes back in one tick; 1
  /// returns at once. In (0, 1].
  double dagger_return = 1.0;
  /// Worker threads (the result does not depend on it). 1: Debian's ODE 0.16 crashed (segfault
  /// in libode) with two worlds stepped on two threads here; more only with an ODE built for it.
  int threads = 1;
};

/// One executed rollout of a demonstration: T − 1 ticks (every sample with a successor), rad.
struct PolicySequence {
  int demo = 0;      ///< index into PolicyData::demos
  int movement = 0;
  int rollout = 0;   ///< 0: clean, k >= 1: noisy rollout k, -i: the policy's rollout of DAgger round i
  std::vector<JointVector> q;       ///< measured q(t) at the start of tick t (q(0) = f(0), at rest)
  std::vector<JointVector> a_prev;  ///< a(t−1) as applied (c(t−1) − q(t−1)), 0 at t = 0
  std::vector<JointVector> r;       ///< reference input: f(t+1) − q(t), f(t+1) the tick's feature-extracted target (clamped)
  std::vector<JointVector> a;       ///< label: the expert's c(t) − q(t)
  double worst_miss_rad = 0.0;      ///< largest |q(t+1) − f(t+1)| of the expert's command (clean rollout)
  double drift_rad = 0.0;           ///< policy rollouts: largest |q(t) − f(t)| (clamped f) the policy reached
  std::size_t expert_ticks = 0;     ///< policy rollouts: ticks that executed the expert's command (β-mixing)
  std::size_t ticks() const { return a.size(); }
};

/// Executes the listed demonstrations (clean + noisy rollouts each, in list order) on the
/// simulated arm of `sim_model` with the controller's per-tick bounds (period = the model's
/// substeps × dt). Seeded: the noise of (demo, rollout) comes from its own splitmix64 stream,
/// so the result does not depend on which other demos are listed or on options.threads.
/// Deterministic (ODE's direct solver). Prints a progress line per 10 % to `progress` if not null. Throws UserError for bad
/// options.
std::vector<PolicySequence> executeDemos(const PolicyData& data, const std::vector<int>& demos,
                                         const SimModel& sim_model, const ExecutionOptions& options,
                                         std::uint64_t seed, std::ostream* progress = nullptr);

/// A policy for executePolicyRollouts: the action a(t), rad, before the controller's clamp, from
/// the inputs the controller gives it (measured q(t), the applied a(t−1), r = f(t+1) − q(t) as
/// for the expert's rollouts) at tick t of demonstration `demo`'s movement. t == 0 starts a new
/// rollout (a streaming policy resets its window there).
using RolloutPolicy = std::function<JointVector(int movement, int t, const JointVector& q, const JointVector& a_prev,
                                                const JointVector& r)>;

/// DAgger (Ross et al. 2011; docs/policy.md "Data"): each listed demonstration rolled out on the
/// simulated arm from its start (at rest at f(0), as executeDemos) for its length, executing the
/// *policy's* action as the controller applies it (q + a clamped to the position limits and
/// v_max·period, a non-finite action replaced by 0; the applied action is the next a(t−1)), and
/// labelled at every visited state by the expert toward the demonstration's f(t+1) exactly as
/// executeDemos labels its rollouts. Round i >= 1 executes the expert's command instead on a
/// seeded share options.dagger_beta^i of the ticks (β-mixing; 0: the pure policy); round 0 is
/// always the pure policy. Deterministic for a deterministic policy. One thread, in list order
/// (the policy may be stateful). Sequences get rollout = −round. With `labels` false (scoring a
/// policy by where it goes) the expert is not run: q, a_prev and r are recorded, `a` stays
/// empty. With options.dagger_align_band > 0 the labelled rounds align every state to the
/// clean executions (rollout 0; others are ignored) in `align_pool`: those of the whole
/// training split, whatever share of it `demos` is, so the labels do not depend on how the
/// rollouts are shared out. r stays the clock's. Throws UserError for bad options or indices,
/// or aligned labels without a clean execution to align to.
std::vector<PolicySequence> executePolicyRollouts(const PolicyData& data, const std::vector<int>& demos,
                                                  const SimModel& sim_model, const ExecutionOptions& options,
                                                  const RolloutPolicy& policy, int round, bool labels = true,
                                                  const std::vector<PolicySequence>& align_pool = {});

/// Normalisation statistics over every tick of `sequences` (q, the labels a, r).
NormStats normStats(const std::vector<PolicySequence>& sequences);

/// Zero-action and repeat-last-action MSE over every tick of `sequences`, rad^2.
Baselines baselines(const std::vector<PolicySequence>& sequences);

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

/// Normalisation statistics of `samples` (the training split's). Throws UserError if empty.
NormStats normStats(const std::vector<PolicySample>& samples);

/// Zero-action and repeat-last-action MSE over `samples` (0 for no samples), rad^2.
Baselines baselines(const std::vector<PolicySample>& samples);

/// FNV-1a 64 over the data set in a canonical little-endian byte form: movement names and
/// centroids, then per demo (name order) its name, movement, and per sample t_s, label,
/// measured, f (f64). Equal data give equal fingerprints on every platform.
std::uint64_t dataFingerprint(const PolicyData& data);

/// 16 lower-case hex digits.
std::string hex64(std::uint64_t value);

/// How the training demonstrations are brought to one pace (autonomous mode; docs/policy.md
/// "Canonical pace"): onto a template demonstration of the movement.
enum class PaceMethod {
  kLinear,  ///< the whole trajectory resampled linearly into the template's sample count
  kDtw,     ///< time-warped onto the template by slope-limited dynamic time warping (dtwWarp)
};
const char* paceMethodName(PaceMethod method);  ///< "linear" / "dtw"
/// "linear" / "dtw"; throws UserError naming the choices for anything else.
PaceMethod parsePaceMethod(const std::string& name);

/// Trajectory f of T samples resampled linearly in time so that the whole of it takes
/// min(pace_ticks, T) samples, then held at its last pose for the rest of its own T samples (the
/// length is unchanged, f(0) and the last pose too). Throws UserError unless pace_ticks >= 2.
std::vector<JointVector> pacedTrajectory(const std::vector<JointVector>& f, int pace_ticks);

/// Dynamic time warping of f (T samples) onto tmpl (L samples) in joint space (Euclidean distance
/// per sample pair), with the steps (1,1), (2,1), (1,2) (f, template) so that the warp's slope
/// stays in [1/2, 2] (no stretch of f sped up more than twice), ties in that order: for each
/// template sample k the position u(k) in f, in samples, from the optimal path (a (1,2) step
/// puts the skipped template sample half-way), smoothed by a centred moving average over 5
/// samples (narrower near the ends), then u(0) = 0, u(L−1) = T−1 and made non-decreasing.
/// nullopt when no such path exists (T − 1 > 2 (L − 1) or L − 1 > 2 (T − 1)). Throws UserError
/// for fewer than 2 samples on either side.
std::optional<std::vector<double>> dtwWarp(const std::vector<JointVector>& f, const std::vector<JointVector>& tmpl);

/// f at the pace of tmpl (L samples): for T <= L, f unchanged; otherwise f's movement in L
/// samples (kLinear: pacedTrajectory(f, L); kDtw: f interpolated linearly at dtwWarp(f, tmpl), or
/// linearly paced when f is more than twice as long as tmpl and no warp exists),
/// then held at f's last pose for the rest of its T samples. Length, f(0) and last pose unchanged.
std::vector<JointVector> pacedTrajectory(const std::vector<JointVector>& f, const std::vector<JointVector>& tmpl,
                                         PaceMethod method);

/// Per movement (index m), the template of its pace: the index of its shortest listed
/// demonstration (the first in list order among equals); -1 for a movement with none listed.
std::vector<int> paceTemplates(const PolicyData& data, const std::vector<int>& demos);

/// `data` with every demonstration of movement m paced onto demonstration templates[m]
/// (pacedTrajectory: f, and the label and measured flag of the nearest original sample); names,
/// times and lengths unchanged. Throws UserError unless there is a valid template per movement.
PolicyData pacedData(const PolicyData& data, const std::vector<int>& templates, PaceMethod method);

/// Names of the listed demonstrations.
std::vector<std::string> demoNames(const PolicyData& data, const std::vector<int>& demos);

}  // namespace nao::tools
