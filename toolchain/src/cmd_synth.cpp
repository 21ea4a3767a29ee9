// `nao_toolchain synth`: synthetic human demonstrations of the paper's three circle movements.
#include "nao/tools/command.hpp"
#include "nao/tools/synth.hpp"

#include <iostream>
#include <memory>

namespace {

struct SynthArgs {
  std::string movement = "all";
  int per_movement = 80;
  std::uint64_t seed = 1;
  std::string out;
  bool noise_free = false;
};

void setup(CLI::App& app) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* cmd = app.add_subcommand(
      "synth",
      "Synthetic demonstrations: a 7-DoF human right arm with sampled anthropometrics draws the paper's\n"
      "three circles (whole arm, elbow-centred, wrist-centred), seen by two virtual 1920x1080 cameras.\n"
      "Writes DIR/<movement>_<index>/ with cam0/ and cam1/ (OpenPose BODY_25 + right-hand JSON per\n"
      "30 Hz frame), calibration.json, truth.csv (3D keypoints and joint angles) and meta.json.\n"
      "The same seed gives byte-identical files. See docs/synth.md and docs/formats.md.");
  cmd->add_option("--movement", args->movement, "whole_arm, elbow, wrist or all")
      ->check(CLI::IsMember({"whole_arm", "elbow", "wrist", "all"}))
      ->capture_default_str();
  cmd->add_option("--per-movement", args->per_movement, "demonstrations per movement (80 = the paper's data set)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "seed of the whole data set")->capture_default_str();
  cmd->add_option("--out", args->out, "output directory")->required();
  cmd->add_flag("--noise-free", args->noise_free,
                "exact projections: no pixel noise, no dropouts, confidence 1, no tremor (for tests)");
  cmd->callback([args] {
    nao::tools::SynthOptions options;
    if (args->movement != "all") options.movements = {nao::tools::parseMovement(args->movement)};
    options.per_movement = args->per_movement;
    options.seed = args->seed;
    options.noise_free = args->noise_free;
    options.out_dir = args->out;
    nao::tools::synthesise(options, std::cout);
  });
}

}  // namespace

NAO_REGISTER_COMMAND(synth, setup)
