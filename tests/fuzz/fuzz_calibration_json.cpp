// Fuzz target: calibration JSON (the runtime's parseCameraSetJson, which nao_rt --calibration
// and the toolchain both use). Either cameras with finite, plausible intrinsics and a proper
// rotation, or InputError naming the source.
#include "calibration_checks.hpp"

#include "nao/calibration_json.hpp"
#include "nao/input_error.hpp"

#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    nao::fuzz::checkCameras(nao::parseCameraSetJson(std::string(reinterpret_cast<const char*>(data), size), "fuzz.json"));
  } catch (const nao::InputError& e) {
    NAO_FUZZ_CHECK(std::string(e.what()).rfind("fuzz.json", 0) == 0);
  }
  return 0;
}
