// Fuzz target: one OpenPose frame (parseOpenPoseJson), read as BODY_25 or BODY_25B by the
// input's length parity. Either people with finite pixels and confidences in [0, 1], or
// UserError naming the source.
#include "fuzz_util.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"

#include <cmath>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace nao::tools;
  const PoseFormat format = size % 2 == 0 ? PoseFormat::kBody25 : PoseFormat::kBody25B;
  try {
    const std::vector<Person2d> people =
        parseOpenPoseJson(std::string(reinterpret_cast<const char*>(data), size), format, "fuzz.json");
    for (const Person2d& p : people)
      for (int i = 0; i < nao::kNumSkeletonPoints; ++i) {
        NAO_FUZZ_CHECK(p.px[i].allFinite());
        NAO_FUZZ_CHECK(p.confidence[i] >= 0.0 && p.confidence[i] <= 1.0);
      }
  } catch (const UserError& e) {
    NAO_FUZZ_CHECK(std::string(e.what()).rfind("fuzz.json", 0) == 0);
  }
  return 0;
}
