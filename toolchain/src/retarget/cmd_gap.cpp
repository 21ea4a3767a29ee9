// nao_toolchain gap: the embodiment gap of held-out synthetic demonstrations, measured.
#include "nao/tools/command.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/tools/embodiment_gap.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/retarget_cli.hpp"

#include <cstdio>
#include <filesystem>
#include <memory>

namespace nao::tools {
namespace {

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "gap",
      "The embodiment gap, measured on synthetic demonstrations seen through the cameras (render,\n"
      "triangulate, retarget): per movement, how much of the human hand path each human DoF draws,\n"
      "how far NAO's hand lands from the scaled human hand with the human's angles clamped to its limits,\n"
      "and what the imitation reference q_r changes (hand miss, joint deviation, shoulder+elbow speed).\n"
      "Use a seed the training set was not made with (training: synth seed 1). Writes\n"
      "OUT/gap_<movement>.csv (docs/formats.md) for the figures of docs/retargeting.md.");
  struct Args {
    std::string movement = "all", out, urdf = NAO_DEFAULT_URDF, solver = "lm";
    int demos = 8;
    std::uint64_t seed = 424242;
    RetargetSettingArgs setting;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("--movement", args->movement, "whole_arm, elbow, wrist or all")
      ->check(CLI::IsMember({"whole_arm", "elbow", "wrist", "all"}))
      ->capture_default_str();
  cmd->add_option("--demos", args->demos, "Demonstrations per movement")->check(CLI::Range(1, 1000))->capture_default_str();
  cmd->add_option("--seed", args->seed, "Synthesiser run seed (not the training set's)")->capture_default_str();
  cmd->add_option("--solver", args->solver, "lm (the runtime's fixed-size solver) or ceres")
      ->check(CLI::IsMember({"ceres", "lm"}))
      ->capture_default_str();
  cmd->add_option("--urdf", args->urdf, "Robot description")->capture_default_str()->check(CLI::ExistingFile);
  cmd->add_option("--out", args->out, "Directory for gap_<movement>.csv (optional)");
  addRetargetSettingOptions(cmd, args->setting);
  cmd->callback([args] {
    const ArmModel arm = loadArmModel(args->urdf);
    RetargetOptions options;
    options.use_ceres = args->solver == "ceres";
    options.params = applyRetargetSetting(args->setting, options.params);
    if (!args->out.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(args->out, ec);
      if (ec) throw UserError("cannot create " + args->out + ": " + ec.message());
    }
    std::printf("gap: seed %llu, %d demonstration(s) per movement, priority %s, solver %s\n",
                static_cast<unsigned long long>(args->seed), args->demos, args->setting.priority.c_str(),
                args->solver.c_str());
    std::printf("%-10s %7s %7s %7s %7s %7s | %9s %9s %8s %9s %8s %7s %7s %6s\n", "movement", "shoulder", "elbow",
                "forearm", "wrist", "spread", "clamp_mm", "qr_mm", "qr<=1cm", "dq_rad", "speed", "frames", "unreach",
                "fallbk");
    for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
      const std::string name = kMovementNames[static_cast<std::size_t>(m)];
      if (args->movement != "all" && args->movement != name) continue;
      HandPathShares mean_shares;
      std::vector<std::vector<GapFrame>> sequences;
      for (int i = 0; i < args->demos; ++i) {
        const SynthDemo demo = generateDemo(m, i, args->seed, false);
        const HandPathShares s = handPathShares(demo);
        mean_shares.shoulder += s.shoulder / args->demos;
        mean_shares.elbow += s.elbow / args->demos;
        mean_shares.forearm += s.forearm / args->demos;
        mean_shares.wrist += s.wrist / args->demos;
        mean_shares.spread_rms_m += s.spread_rms_m / args->demos;
        sequences.push_back(embodimentGap(arm, retargetSkeleton(arm, observeDemo(demo), options)));
        std::fprintf(stderr, "gap: %s %d/%d\r", name.c_str(), i + 1, args->demos);
      }
      const GapSummary g = summariseGap(sequences);
      std::printf("%-10s %7.2f %7.2f %7.2f %7.2f %5.1fcm | %9.2f %9.3f %7.1f%% %9.3f %8.2f %7d %7d %6d\n",
                  name.c_str(), mean_shares.shoulder, mean_shares.elbow, mean_shares.forearm, mean_shares.wrist,
                  100.0 * mean_shares.spread_rms_m, 1e3 * g.median_clamp_miss_m, 1e3 * g.median_r_miss_m,
                  100.0 * g.frac_r_within_1cm_reachable, g.median_dq_rad, g.speed_ratio_shoulder_elbow, g.frames,
                  g.unreachable, g.fallbacks);
      if (!args->out.empty()) writeGapCsv((std::filesystem::path(args->out) / ("gap_" + name + ".csv")).string(), sequences);
    }
    std::printf("shares: hand-path spread each human DoF group draws in the circle phase; clamp_mm / qr_mm: median\n"
                "hand miss of the clamped human angles / of q_r; qr<=1cm: among the frames NAO can reach (unreach: no\n"
                "pose inside the limits comes within 1 cm); dq_rad: median |q_r - clamp|; speed: RMS\n"
                "shoulder+elbow angular speed of q_r over that of the clamp (docs/retargeting.md)\n");
  });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(gap, nao::tools::setup)
