// Fuzz target: model.bin (decodeModel). Any input either decodes into a model that keeps the
// format's promises or is refused with ModelFileError; nothing else may happen.
#include "fuzz_util.hpp"

#include "nao/model_file.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const nao::ModelFile m = nao::decodeModel(std::vector<std::uint8_t>(data, data + size), "fuzz.bin");
    NAO_FUZZ_CHECK(nao::archProblem(m.header.arch).empty());
    NAO_FUZZ_CHECK(m.header.joints.size() == static_cast<std::size_t>(m.header.arch.tokens));
    for (const nao::TrainedJoint& j : m.header.joints) {
      NAO_FUZZ_CHECK(std::isfinite(j.lower) && std::isfinite(j.upper) && j.lower < j.upper);
      NAO_FUZZ_CHECK(std::isfinite(j.velocity) && j.velocity > 0.0);
    }
    for (const nao::TensorEntry& t : m.tensors)
      NAO_FUZZ_CHECK(t.offset + 4 * t.spec.count() <= m.bytes.size() - 8);
  } catch (const nao::ModelFileError&) {
  }
  return 0;
}
