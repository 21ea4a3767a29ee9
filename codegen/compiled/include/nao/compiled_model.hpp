// The model compiled into nao_rt at build time (models/default.bin through nao_codegen): its
// bytes, exactly as the file holds them, in read-only data, and what the generated
// nao_model_config.hpp states about them as constants (header fields, tensor offsets). Exists
// only in builds with NAO_HAVE_COMPILED_MODEL (the nao_compiled_model library).
//
// Start-up binds the policy's fixed-size views at the generated offsets into .rodata
// (bindPolicyWeightsAt): no decode, no copy, no name lookup; the checksum is verified once over
// the bytes (checkModelImage, mappedModelFile).
#pragma once

#include "nao/model_file.hpp"
#include "nao_model_dims.hpp"

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

/// The embedded model with its generated constants: the header (built from them on the first
/// call: configure time, allocates its strings), the checksum and the tensor offsets.
ModelImage modelImage();

/// The policy's weights bound at the generated offsets (bindPolicyWeightsAt). No allocation,
/// no check: call checkModelImage (or mappedModelFile) on modelImage() once before trusting them.
PolicyWeights<Dims> policyWeights() noexcept;

}  // namespace nao::compiled
