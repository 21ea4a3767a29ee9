// nao_toolchain calibration --to-json IN OUT: a calibration (our JSON or an OpenCV/Anipose-style
// TOML) as our JSON, the form nao_rt reads (nao_rt links no TOML parser).
#include "nao/file_io.hpp"
#include "nao/tools/calibration.hpp"
#include "nao/tools/command.hpp"

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace nao::tools {
namespace {

void setup(CLI::App& app) {
  auto paths = std::make_shared<std::vector<std::string>>();
  CLI::App* cmd = app.add_subcommand(
      "calibration",
      "Convert a camera calibration: our .json or an OpenCV/Anipose-style .toml in, our JSON out (what\n"
      "nao_rt --calibration reads). Every camera is checked as triangulate checks it. See docs/formats.md.");
  cmd->add_option("--to-json", *paths, "IN OUT: the calibration to read (.json or .toml) and the JSON file to write")
      ->expected(2)
      ->required();
  cmd->callback([paths] {
    const std::string& in = (*paths)[0];
    const std::string& out = (*paths)[1];
    const CameraSet cameras = readCalibration(in);
    const std::string text = formatCalibrationJson(cameras) + "\n";
    const std::string problem = writeFileAtomically(out, text.data(), text.size());
    if (!problem.empty()) throw UserError("cannot write " + out + ": " + problem);
    std::printf("%zu cameras from %s written to %s\n", cameras.size(), in.c_str(), out.c_str());
  });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(calibration, nao::tools::setup)
