// Fuzz target: calibration JSON (parseCalibrationJson). Either cameras with finite, plausible
// intrinsics and a proper rotation, or UserError naming the source.
#include "calibration_checks.hpp"

#include "nao/tools/calibration.hpp"
#include "nao/tools/command.hpp"

#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    nao::fuzz::checkCameras(
        nao::tools::parseCalibrationJson(std::string(reinterpret_cast<const char*>(data), size), "fuzz.json"));
  } catch (const nao::tools::UserError& e) {
    NAO_FUZZ_CHECK(std::string(e.what()).rfind("fuzz.json", 0) == 0);
  }
  return 0;
}
