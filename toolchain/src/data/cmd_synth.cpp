// `nao_toolchain synth`: synthetic human demonstrations of the paper's three circle movements.
#include "nao/tools/command.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/synth_stress.hpp"

#include <iostream>
#include <memory>

namespace {

struct SynthArgs {
  std::string movement = "all";
  int per_movement = 80;
  std::uint64_t seed = 1;
  std::string out;
  bool noise_free = false;
  int stress_cameras = 0;
  int stress_frames = 0;
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
  cmd->add_option("--stress-cameras", args->stress_cameras,
                  "instead of the demonstrations, write stress recordings <movement>_<index>_stress/ seen by N\n"
                  "cameras at 60 fps: a second person crossing, left/right arm swaps in cam1, wrong confident\n"
                  "arm keypoints in cam2, per-camera dropouts (docs/synth.md); 0: off")
      ->check(CLI::Range(0, 16));
  cmd->add_option("--stress-frames", args->stress_frames, "frames per stress recording (0: the whole demonstration)")
      ->check(CLI::NonNegativeNumber);
  cmd->callback([args] {
    if (args->stress_cameras > 0) {
      nao::tools::StressOptions stress;
      stress.n_cameras = args->stress_cameras;
      stress.n_frames = args->stress_frames;
      stress.seed = args->seed;
      if (stress.n_cameras < 3) stress.wrong_camera = -1;
      if (stress.n_cameras < 2) throw nao::tools::UserError("--stress-cameras needs at least 2 cameras");
      std::vector<nao::tools::Movement> movements = {nao::tools::Movement::kWholeArm, nao::tools::Movement::kElbow,
                                                     nao::tools::Movement::kWrist};
      if (args->movement != "all") movements = {nao::tools::parseMovement(args->movement)};
      for (nao::tools::Movement m : movements)
        for (int i = 0; i < args->per_movement; ++i) {
          const auto scene = nao::tools::renderStressScene(nao::tools::generateDemo(m, i, args->seed, args->noise_free), stress);
          nao::tools::writeStressScene(scene, args->out);
          std::cout << scene.name << ": " << scene.truth.size() << " frames at " << scene.fps << " Hz, "
                    << scene.cameras.size() << " cameras\n";
        }
      return;
    }
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
