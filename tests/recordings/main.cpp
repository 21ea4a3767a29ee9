// nao_test_recordings: writes two-camera OpenPose recordings of movements the synthesiser does
// not draw (wave, reach, side_raise), for the retargeting tests and the system test.
#include "recordings.hpp"

#include <CLI/CLI.hpp>

#include <iostream>
#include <sstream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  CLI::App app{
      "nao_test_recordings: two calibrated 30 fps cameras' OpenPose BODY_25 JSON (+ right-hand points 0, 5, 9, 17)\n"
      "of movements the synthesiser does not draw, one folder DIR/<movement>_<index>/ per recording (cam0/,\n"
      "cam1/, calibration.json, truth.csv, meta.json), as `nao_toolchain triangulate --demo` reads it.\n"
      "Movements: wave (the hand waving above the shoulder), reach (forward to shoulder height, a pause,\n"
      "back), side_raise (the arm swung up sideways through the horizontal). 6-10 s each; subject, speed,\n"
      "amplitude and start pose vary per recording. The same seed gives byte-identical files."};
  nao::recordings::Options options;
  std::string movements = "wave,reach,side_raise";
  app.add_option("--out", options.out_dir, "Output folder")->required();
  app.add_option("--movements", movements, "Comma-separated movements")->capture_default_str();
  app.add_option("--per-movement", options.per_movement, "Recordings per movement")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--seed", options.seed, "Seed")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "nao_test_recordings: " << e.what() << "\n";
    return 2;
  }
  options.movements.clear();
  std::stringstream list(movements);
  for (std::string m; std::getline(list, m, ',');)
    if (!m.empty()) options.movements.push_back(m);
  try {
    const int n = nao::recordings::writeRecordings(options, std::cout);
    std::cout << n << " recordings in " << options.out_dir << "\n";
  } catch (const std::invalid_argument& e) {
    std::cerr << "nao_test_recordings: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "nao_test_recordings: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
