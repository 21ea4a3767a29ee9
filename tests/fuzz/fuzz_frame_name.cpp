// Fuzz target: the frame index of an OpenPose file name (openPoseFrameIndex, run on every file
// name a watched camera folder reports), checked against the two regular expressions it stands
// for: [<name>_]<12 digits>_keypoints.json and <name>.<digits>.json (at most 18 digits).
#include "fuzz_util.hpp"

#include "nao/openpose_json.hpp"

#include <optional>
#include <regex>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 512) return 0;  // file names are short; std::regex recurses on long inputs
  const std::string name(reinterpret_cast<const char*>(data), size);
  static const std::regex kOpenPoseName(R"(^(?:.*_)?([0-9]{12})_keypoints\.json$)");
  static const std::regex kDottedName(R"(^.*\.([0-9]+)\.json$)");
  std::optional<long long> expected;
  std::smatch m;
  if (std::regex_match(name, m, kOpenPoseName) || std::regex_match(name, m, kDottedName))
    if (m[1].str().size() <= 18) expected = std::stoll(m[1].str());
  NAO_FUZZ_CHECK(nao::openPoseFrameIndex(name) == expected);
  return 0;
}
