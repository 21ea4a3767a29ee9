// From a 3D human skeleton sequence to NAO joint trajectories offline: the runtime's sequence
// retargeting (nao/retarget_sequence.hpp) with the Ceres solver, and the retarget CSV.
#pragma once

#include "nao/human_kinematics.hpp"
#include "nao/retarget.hpp"
#include "nao/retarget_sequence.hpp"
#include "nao/tools/retarget_ceres.hpp"
#include "nao/tools/skeleton_csv.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace nao::tools {

// The per-frame targets and the sequence loop are the runtime's (nao/retarget_sequence.hpp).
using nao::kRowHandNotSeen;
using nao::kRowHumanMissing;
using nao::RetargetFrameSolver;
using nao::RetargetOptions;
using nao::RetargetRow;
using nao::RetargetRowFlags;
using nao::retargetSkeletonLm;
using nao::retargetSkeletonWith;
using nao::retargetTargets;

/// retargetSkeletonWith the solver options.use_ceres names: Ceres (offline reference) or the
/// runtime's LM (retargetSkeletonLm). Defined in retarget_ceres.cpp: links Ceres
/// (nao_toolchain_lib, not nao_reference).
std::vector<RetargetRow> retargetSkeleton(const ArmModel& arm, const Skeleton& frames, const RetargetOptions& options);

/// Header and rows of the retarget CSV; `params` holds the setting the rows' q_r was made with
/// (priority, lambda_q, posture weights: written on every row). Throws UserError if the file
/// cannot be written.
void writeRetargetCsv(const std::string& path, const std::vector<RetargetRow>& rows, const RetargetParams& params);

/// Reads a retarget CSV back (t_s, q_x, q_q, x_target, hands reached, flags, q_target, q_r) and,
/// when `setting` is given, writes the retargeting setting of its q_r into it (priority,
/// lambda_q, posture_weights; other fields untouched). Throws UserError naming the file, line and
/// column for a missing column or a bad value, or for rows of mixed settings.
std::vector<RetargetRow> readRetargetCsv(const std::string& path, RetargetParams* setting = nullptr);

/// True when a and b choose q_r the same way (priority, lambda_q, posture weights).
bool sameRetargetSetting(const RetargetParams& a, const RetargetParams& b);

/// {"priority": "hand"|"joints", "lambda_q": x, "posture_weights": [5]}: the retargeting setting
/// as centroids.json and model.bin metadata record it (nao_rt applies it: runtime/app).
nlohmann::json retargetSettingJson(const RetargetParams& params);

}  // namespace nao::tools
