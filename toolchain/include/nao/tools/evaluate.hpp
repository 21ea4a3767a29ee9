// `nao_toolchain evaluate` (docs/evaluate.md): the paper's autonomous protocol - the model rolled
// out by nao_rt from every held-out demonstration's start - scored by whether it makes the
// movement, against the baselines the data give (the medoid replay, the linear AR model), and the
// reference-mode bar. The pieces here are the ones the tests check on their own. Offline code
// (nao_eval_lib, links nao_metrics): allocates, may throw.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/retarget.hpp"
#include "nao/robot_backend.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/tools/movement_metrics.hpp"
#include "nao/tools/policy_dataset.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

/// Hand points (torso frame, m) of a joint trajectory by forward kinematics.
HandPath handPath(const ArmModel& arm, const std::vector<JointVector>& q);

/// Median of `v` (mean of the two middle values for an even count); NaN when empty.
double median(std::vector<double> v);

/// The demonstration of `demos` nearest to `path` by rt::dtwMeanDistance(path, demo), skipping
/// index `exclude` (-1: none). Ties go to the lower index.
struct NearestDemo {
  double dtw_m = 0.0;
  int index = -1;
};
NearestDemo nearestDemo(const HandPath& path, const std::vector<HandPath>& demos, int exclude = -1);

/// A movement's held-out demonstrations as the runs are scored against them (docs/evaluate.md):
/// their hand paths, the plane loops are counted in (loopPlane of them all) and, per
/// demonstration, the DTW to its nearest other one, its middle-phase RMS speed and its loops.
struct HeldOutScores {
  std::vector<HandPath> hand;
  double period_s = 0.1;
  Eigen::Matrix<double, 3, 2> plane = Eigen::Matrix<double, 3, 2>::Zero();
  std::vector<double> nn_dtw_m, speed_m_s, loops;
};
HeldOutScores scoreHeldOut(std::vector<HandPath> hand, double period_s);

/// One run's hand path scored against the held-out demonstrations: the nearest of them by DTW,
/// the middle-phase RMS speed and the loops in their plane.
struct RunScore {
  NearestDemo nearest;
  double speed_m_s = 0.0;
  double loops = 0.0;
};
RunScore scoreRun(const HandPath& run, const HeldOutScores& held);

/// Per run, its middle-phase RMS hand speed (middleRmsSpeed) divided by its replay's: `replays[i]`
/// is run i's medoid replay (the demonstration it plays, tracked from the same start for as many
/// ticks), so 1 is a run at the speed of what it plays, whatever the held-out demonstrations'
/// speed. NaN where either has no middle stretch or the replay holds still. Throws
/// std::invalid_argument when the counts differ.
std::vector<double> speedVsReplay(const std::vector<HandPath>& runs, const std::vector<HandPath>& replays,
                                  double period_s);

/// The demonstrations of one movement an evaluation uses: their names, feature-extracted
/// trajectories f (the model's key poses), starts and hand paths.
struct DemoSet {
  std::vector<std::string> names;
  std::vector<std::vector<JointVector>> f;  ///< rad, 10 Hz
  std::vector<JointVector> start;           ///< the retargeted pose at the first measured sample, rad
  std::vector<HandPath> hand;               ///< handPath(f)
  std::size_t size() const { return names.size(); }
};

/// The demonstrations of `data` (a clustered data set) of movement `movement` named in `names`,
/// in that order. Throws UserError for a name the data set does not hold.
DemoSet demoSetFrom(const ArmModel& arm, const PolicyData& data, const std::string& movement,
                    const std::vector<std::string>& names);

/// The recordings of a folder (docs/formats.md): its <movement>_<index> sub-folders that hold
/// cam*/ folders, sorted. Throws UserError when there is none.
std::vector<std::string> recordingNames(const std::string& dir);

/// Recording `name` of `dir` as a model sees a demonstration: triangulated as nao_toolchain
/// triangulate does by default (recordingOptions, `fps`, `format`), retargeted with `retarget` (the
/// model's setting, Ceres), snapped to `key_poses` (featureTrajectory on the 10 Hz grid), its start
/// the retargeted pose at its first measured sample. Throws UserError naming the recording.
struct RecordingInput {
  double fps = 30.0;
  std::string format = "body25";
};
PolicyDemo processRecording(const ArmModel& arm, const std::string& dir, const std::string& name,
                            const RecordingInput& input, const RetargetParams& retarget,
                            const std::vector<JointVector>& key_poses);

/// `names` of `dir` processed (processRecording) into a DemoSet, with progress on stderr.
DemoSet demoSetFromRecordings(const ArmModel& arm, const std::string& dir, const std::vector<std::string>& names,
                              const RecordingInput& input, const RetargetParams& retarget,
                              const std::vector<JointVector>& key_poses, const std::string& what);

/// A demonstration's feature trajectory `f` tracked from `start` for `ticks` ticks through the
/// simulated arm by the first-order servo inversion a = g (clamp(f(t+1)) - q) (the rollout step
/// nao_rt takes), f held at its last sample when the run outlasts it. Returns the start, then the
/// measured q after each tick.
std::vector<JointVector> trackDemo(const SimModel& sim, double period_s, double gain, const std::vector<JointVector>& f,
                                   const JointVector& start, int ticks);
/// The same through `robot`, a backend of `arm` (the trainer's copy of the arm: arm_copy.hpp).
std::vector<JointVector> trackDemo(const ArmModel& arm, RobotBackend& robot, double period_s, double gain,
                                   const std::vector<JointVector>& f, const JointVector& start, int ticks);
/// That rollout itself (q after each tick, the applied actions, the hand path).
Rollout trackDemoRollout(const ArmModel& arm, RobotBackend& robot, double period_s, double gain,
                         const std::vector<JointVector>& f, const JointVector& start, int ticks);

/// The replays of a run's neighbours: the `k` training demonstrations whose starts are nearest
/// `start` (nearestStarts order), each tracked from `start` for `ticks` ticks by trackDemo, and
/// which of them is their medoid by summed hand-path DTW (the medoid replay: the best fixed
/// trajectory the data give). The median over all k is what a policy that faithfully plays one
/// of its start's demonstrations, picked at random, would score.
struct NeighbourReplays {
  std::vector<int> demos;                    ///< indices into `train`, nearest first
  std::vector<std::vector<JointVector>> q;   ///< per demonstration: the start, then q after each tick
  int medoid = -1;                           ///< index into `train` (one of `demos`)
  std::size_t medoidSlot() const {  ///< the medoid's place in `demos` and `q`
    return static_cast<std::size_t>(std::find(demos.begin(), demos.end(), medoid) - demos.begin());
  }
  const std::vector<JointVector>& medoidQ() const { return q[medoidSlot()]; }
};
NeighbourReplays neighbourReplays(const SimModel& sim, double period_s, double gain, const DemoSet& train,
                                  const JointVector& start, int ticks, std::size_t k = kRunCodeNearest);

/// Writes a demonstration's f as docs/evaluate.md's demos/<name>.csv: t_s, q_0..q_4 (exact).
void writeTrajectoryCsv(const std::string& path, const std::vector<JointVector>& q, double period_s);

}  // namespace nao::tools
