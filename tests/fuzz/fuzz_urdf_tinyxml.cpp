// Fuzz target: URDF text -> ArmModel through the TinyXML reader of the static robot build
// (parseUrdfTinyXml + armModelFromUrdf, runtime/io/include/nao/urdf_reader.hpp), behind the same text
// guard as parseArmModel. Either a rejection with a reason, an arm whose numbers are usable, or
// ArmModelError.
#include "fuzz_util.hpp"

#include "nao/text_guard.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/urdf_reader.hpp"

#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string xml(reinterpret_cast<const char*>(data), size);
  // parseArmModel bounds the text before any XML parser sees it (TinyXML recurses per element).
  if (!nao::xmlShapeProblem(xml).empty()) return 0;
  std::string reason;
  const auto urdf = nao::parseUrdfTinyXml(xml, reason);
  if (!urdf) {
    NAO_FUZZ_CHECK(!reason.empty());
    return 0;
  }
  try {
    const nao::ArmModel arm = nao::armModelFromUrdf(*urdf, "fuzz.urdf");
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
