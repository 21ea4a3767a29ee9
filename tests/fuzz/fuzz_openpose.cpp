// Fuzz target: one OpenPose frame (the runtime's parseOpenPoseFrame, which nao_rt's live camera
// reader and the toolchain both use), read as BODY_25 or BODY_25B by the input's length parity.
// Either people with finite pixels and confidences in [0, 1], or InputError naming the source.
// Any prefix of an accepted text that is shorter (a half-written file) must be refused or read
// the same people: never other people.
#include "fuzz_util.hpp"

#include "nao/input_error.hpp"
#include "nao/openpose_json.hpp"

#include <cmath>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace nao;
  const PoseFormat format = size % 2 == 0 ? PoseFormat::kBody25 : PoseFormat::kBody25B;
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const std::vector<Person2d> people = parseOpenPoseFrame(text, format, "fuzz.json");
    for (const Person2d& p : people)
      for (int i = 0; i < kNumSkeletonPoints; ++i) {
        NAO_FUZZ_CHECK(p.px[i].allFinite());
        NAO_FUZZ_CHECK(p.confidence[i] >= 0.0 && p.confidence[i] <= 1.0);
      }
    // The live reader parses files while they are written: a cut-off text is either refused or
    // (only trailing whitespace cut) the same frame.
    const std::string half = text.substr(0, size / 2);
    try {
      const std::vector<Person2d> early = parseOpenPoseFrame(half, format, "fuzz.json");
      NAO_FUZZ_CHECK(early.size() == people.size());
    } catch (const InputError&) {
    }
  } catch (const InputError& e) {
    NAO_FUZZ_CHECK(std::string(e.what()).rfind("fuzz.json", 0) == 0);
  }
  return 0;
}
