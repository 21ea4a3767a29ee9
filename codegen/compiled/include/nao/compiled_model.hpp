// The model compiled into nao_rt at build time (models/default.bin through nao_codegen):
// its bytes, exactly as the file holds them, in read-only data. Exists only in builds with
// NAO_HAVE_COMPILED_MODEL (the nao_compiled_model library); the generated
// nao_model_config.hpp next to it describes the same bytes as constexpr values.
#pragma once

#include <cstddef>
#include <cstdint>

namespace nao::compiled {

/// A read-only byte range (pointer and size).
struct ModelBytes {
  const std::uint8_t* data = nullptr;  ///< 64-byte aligned: tensor offsets stay aligned in memory
  std::size_t size = 0;
  const std::uint8_t* begin() const { return data; }
  const std::uint8_t* end() const { return data + size; }
};

/// The embedded model.bin. Real-time safe (no allocation, no I/O).
ModelBytes modelBytes();

}  // namespace nao::compiled
