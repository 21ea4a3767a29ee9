// nao_toolchain retarget: a triangulated (or ground-truth) skeleton CSV -> NAO joint trajectories.
#include "nao/tools/command.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/tools/retarget_cli.hpp"
#include "nao/tools/retarget_pipeline.hpp"

#include <cstdio>

namespace nao::tools {
namespace {

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "retarget",
      "Map a human skeleton sequence onto the NAO V6 arm (paper Algorithm 1): per frame the hand target\n"
      "x_target = robot shoulder + (d_r/d_h) p_h and the human joint angles q_target give q_x\n"
      "(end-effector priority: the hand on x_target, the human's posture in the null space) and q_q\n"
      "(joint priority: the human's angles, the hand pulled toward x_target by lambda_q), inside the\n"
      "URDF limits, and the imitation reference q_r, one of the two by --priority. Each sample starts from\n"
      "the previous one's pose, prefers poses near it (motion cost) and moves no joint faster than its\n"
      "URDF velocity limit over the sample interval, so q_r is a trajectory NAO can execute even where\n"
      "the human leaves its reach. Writes t_s, qx_0..4, qq_0..4, xt_*, ex_*, eq_*, flags, qt_0..4,\n"
      "qr_0..4, priority, lambda_q, pw_0..4 (docs/formats.md).");
  struct Args {
    std::string skeleton, out, urdf = NAO_DEFAULT_URDF, solver = "ceres";
    RetargetSettingArgs setting;
    bool pointing = false;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("--skeleton", args->skeleton, "Skeleton CSV (nao_toolchain triangulate, or a synthesiser truth.csv)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", args->out, "Output CSV")->required();
  cmd->add_option("--urdf", args->urdf, "Robot description")->capture_default_str()->check(CLI::ExistingFile);
  cmd->add_option("--solver", args->solver, "ceres (offline reference) or lm (the runtime's fixed-size solver)")
      ->check(CLI::IsMember({"ceres", "lm"}))
      ->capture_default_str();
  cmd->add_flag("--pointing", args->pointing,
                "Also target the hand's pointing direction when the hand is seen (NAO has no wrist pitch: the\n"
                "solve then trades position for direction and can settle in one of several poses)");
  addRetargetSettingOptions(cmd, args->setting);
  cmd->callback([args] {
    const ArmModel arm = loadArmModel(args->urdf);
    const Skeleton frames = readSkeletonCsv(args->skeleton);
    if (frames.empty()) throw UserError(args->skeleton + ": no frames");
    RetargetOptions options;
    options.use_ceres = args->solver == "ceres";
    options.use_pointing = args->pointing;
    options.params = applyRetargetSetting(args->setting, options.params);
    const std::vector<RetargetRow> rows = retargetSkeleton(arm, frames, options);
    writeRetargetCsv(args->out, rows, options.params);
    int missing = 0, unreachable = 0, capped = 0, fallback = 0, step_bound = 0;
    for (const RetargetRow& r : rows) {
      missing += (r.flags & kRowHumanMissing) != 0;
      unreachable += (r.flags & kRetargetXUnreachable) != 0;
      capped += (r.flags & (kRetargetXCapHit | kRetargetQCapHit | kRetargetInnerCapHit)) != 0;
      fallback += (r.flags & kRetargetFallback) != 0;
      step_bound += (r.flags & kRetargetStepBound) != 0;
    }
    std::printf("retarget: %zu frames -> %s (%s, priority %s): %d without a human arm (held), %d with x_target out "
                "of reach, %d at an iteration cap, %d fell back to the clamped human angles, %d held to the joint "
                "velocity limits\n",
                rows.size(), args->out.c_str(), args->solver.c_str(), args->setting.priority.c_str(), missing, unreachable,
                capped, fallback, step_bound);
  });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(retarget, nao::tools::setup)
