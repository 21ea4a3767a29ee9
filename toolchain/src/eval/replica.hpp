// An autonomous run of nao_rt replayed in process (docs/evaluate.md): the runtime's own
// controller, policy step and ODE arm, tick by tick as nao_rt runs them - so the evaluation can
// look inside every tick: the network's share of the action and the attention ablation (the
// action with each body part left out of the decoder's cross-attention). Offline code.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/sim_arm.hpp"
#include "nao/tools/attention_ablation.hpp"  // ablatedAction, for the replay (replica.cpp)

#include <array>
#include <vector>

namespace nao::tools {

/// One tick of a replayed run.
struct ReplicaTick {
  JointVector q = JointVector::Zero();    ///< measured at the end of the tick, rad (ticks.csv q_*)
  JointVector a = JointVector::Zero();    ///< the action before the command limits, rad
  JointVector net = JointVector::Zero();  ///< the network's share of it (a less the model's law), rad
  std::array<float, 5> mass{};            ///< the last decoder layer's cross-attention mass per body part
  std::array<double, 5> delta{};          ///< ||a(body part j left out) - a||, rad
};

/// True if the toolchain can replay runs of `model` (its dimensions are the toolchain's: toolchain_dims.hpp).
bool canReplay(const ModelFile& model);

/// nao_rt --reference none --start-pose `start` --ticks `ticks` on the ODE arm, replayed: the
/// model's weights bound as nao_rt binds a --weights file, the controller configured with its
/// defaults. Throws UserError unless canReplay(model).
std::vector<ReplicaTick> replayAutonomousRun(const ModelFile& model, const ArmModel& arm, const SimParams& sim,
                                             int movement, const JointVector& start, int ticks);

/// Writes `ticks` as ablation.csv (tick, mass_0..4, delta_0..4; docs/analysis.md), 9 significant
/// digits for the masses (they must match attention.bin's float32 record).
void writeAblationCsv(const std::string& path, const std::vector<ReplicaTick>& ticks);

}  // namespace nao::tools
