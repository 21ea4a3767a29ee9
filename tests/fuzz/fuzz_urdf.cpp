// Fuzz target: URDF text -> ArmModel (parseArmModel: the text guard, urdfdom/TinyXML, the
// arm checks). Either an arm whose numbers are usable or ArmModelError.
#include "fuzz_util.hpp"

#include "nao/arm_model.hpp"
#include "nao/arm_model_io.hpp"

#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const nao::ArmModel arm = nao::parseArmModel(std::string(reinterpret_cast<const char*>(data), size), "fuzz.urdf");
    for (int j = 0; j < nao::kNumJoints; ++j) {
      NAO_FUZZ_CHECK(arm.p_PJ[j].allFinite() && arm.p_PJ[j].cwiseAbs().maxCoeff() < 10.0);
      NAO_FUZZ_CHECK(arm.R_PJ[j].allFinite() && arm.axis_J[j].allFinite());
      NAO_FUZZ_CHECK(arm.q_min[j] < arm.q_max[j] && arm.v_max[j] > 0.0 && arm.tau_max[j] > 0.0);
      NAO_FUZZ_CHECK(arm.link[j].mass > 0.0 && arm.link[j].I_C.allFinite());
    }
    NAO_FUZZ_CHECK(arm.p_WH.allFinite() && arm.p_WH.cwiseAbs().maxCoeff() < 10.0);
  } catch (const nao::ArmModelError&) {
  }
  return 0;
}
