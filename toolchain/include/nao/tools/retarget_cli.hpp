// The retargeting setting on a command line (retarget, gap): --priority, --lambda-q,
// --posture-weights, with one help text.
#pragma once

#include "nao/retarget.hpp"

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace nao::tools {

struct RetargetSettingArgs {
  std::string priority = "hand";
  double lambda_q = RetargetParams{}.lambda_q;
  std::vector<double> posture_weights = std::vector<double>(kNumJoints, 1.0);
};

/// Adds the three options to `cmd`, writing into `args` (which must outlive parsing).
void addRetargetSettingOptions(CLI::App* cmd, RetargetSettingArgs& args);

/// `params` with the parsed setting applied.
RetargetParams applyRetargetSetting(const RetargetSettingArgs& args, RetargetParams params = {});

}  // namespace nao::tools
