#include "nao/compiled_model.hpp"

#include "nao/model_file.hpp"
#include "nao_model_config.hpp"

// Defined by the generated nao_model_weights.S.
extern "C" const std::uint8_t nao_model_blob[];
extern "C" const std::uint8_t nao_model_blob_end[];

namespace nao::compiled {

ModelBytes modelBytes() {
  return {nao_model_blob, static_cast<std::size_t>(nao_model_blob_end - nao_model_blob)};
}

static_assert(kFormatVersion == kModelFormatVersion, "the generated config is of another model.bin format");

}  // namespace nao::compiled
