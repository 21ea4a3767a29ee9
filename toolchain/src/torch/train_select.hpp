// Model selection on autonomous rollouts (docs/policy.md "Model selection"): the net rolled out
// through the runtime's own streaming inference from the validation demonstrations' starts, and
// scored the way `nao_toolchain evaluate` scores runs. Offline only (libtorch).
#pragma once

#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/movement_metrics.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"

#include <Eigen/Core>

#include <vector>

namespace nao::tools {

struct EpochStats;

/// True if the toolchain holds the runtime's step for `arch`'s computation (hasToolchainDims;
/// any table sizes, a chunk up to the runtime's bound). Other
/// computations are rolled out by the nao_rt built for them (`toolchain/nao build --model`).
bool hasRuntimeStep(const PolicyArch& arch);

/// `net`'s runs from each listed demonstration's start (rolloutPolicy over `data`, whose f(0) are
/// the starts), its present weights bound to the runtime's stepPolicy as nao_rt binds them; the
/// step row is the tick; with `codes` (per movement, nullptr: none) each run takes the code the
/// controller would give it (runCodeIndex of its start). Throws UserError unless
/// hasRuntimeStep(net->arch()).
std::vector<PolicyRun> netRuns(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                               const PolicyNet& net, const std::vector<ModelRunCodes>* codes = nullptr);

/// What runs of each movement are measured against: its validation demonstrations' hand paths,
/// the plane loops are counted in, their middle-phase speeds and loops, and the joint range of
/// all the movement's demonstrations in the data.
struct SelectionReference {
  std::vector<std::vector<HandPath>> demos;  ///< [movement][validation demonstration]
  std::vector<Eigen::Matrix<double, 3, 2>> plane;
  std::vector<double> demo_speed, demo_loops;  ///< medians per movement
  std::vector<JointVector> q_min, q_max;       ///< per movement
  std::vector<double> nn_dtw_m;                ///< per movement: the demonstrations' own nearest-neighbour DTW
  /// With run codes: per movement, the hand path of each code's demonstration (the run codes' order).
  std::vector<std::vector<HandPath>> code_paths;
  /// Empty, or per demonstration of the data (NaN for a training one): the middle-phase speed of
  /// the medoid replay from its start (its code's demonstration tracked by the gain law for as
  /// many ticks as its run), which a run's speed is then measured against (addReplaySpeeds).
  std::vector<double> replay_speed;
};
/// `codes` (nullptr: none): the run codes the runs take, whose demonstrations' paths a run's
/// code fidelity is measured against.
SelectionReference selectionReference(const PolicyData& data, const std::vector<int>& val, const ArmModel& arm,
                                      double period_s, const std::vector<ModelRunCodes>* codes = nullptr);

/// Fills ref.replay_speed for the validation demonstrations `val` of `data` (`codes` per movement:
/// the code a run from a demonstration's start takes, runCodeIndex): each run's speed is then
/// measured against what it plays (speed_vs_replay) instead of the validation demonstrations'.
void addReplaySpeeds(SelectionReference& ref, const PolicyData& data, const std::vector<int>& val, const SimModel& sim,
                     double period_s, const std::vector<ModelRunCodes>& codes);

/// Scores `runs` into `st` (rollout_dtw_m, makes_movement, rollouts): per movement the medians of
/// the DTW to the nearest validation demonstration, of the speed ratio and of the loops, and the
/// worst excursion beyond the joint range; a movement is made when its runs meet the bars
/// (EpochStats::makes_movement; with ref.replay_speed, the speed bar on speed_vs_replay). With `codes` (and ref.code_paths) also each run's code
/// fidelity: the DTW to the demonstration whose code it takes (runCodeIndex of its start),
/// their median per movement and its mean over movements. A non-finite run scores NaN (never kept).
void scoreRuns(const std::vector<PolicyRun>& runs, const SelectionReference& ref, const ArmModel& arm, double period_s,
               EpochStats& st, const std::vector<ModelRunCodes>* codes = nullptr);

/// True if epoch `a` is better than `b` for selection: one that makes the movement over one that
/// does not, then the lower rollout DTW (a NaN never wins). `by_fidelity`: among the epochs whose
/// runs keep within the demonstrations' joint range + 0.1 rad, the lower mean code fidelity (a
/// run-code model trained to play its codes: the speed and loops of the demonstrations its codes
/// name are what it should have, whatever the held-out ones' are).
bool betterEpoch(const EpochStats& a, const EpochStats& b, bool by_fidelity = false);

}  // namespace nao::tools
