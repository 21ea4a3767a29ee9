#include "nao/compiled_model.hpp"

#include "nao_model_config.hpp"

// Defined by the generated nao_model_weights.S.
extern "C" const std::uint8_t nao_model_blob[];
extern "C" const std::uint8_t nao_model_blob_end[];
extern "C" const std::uint8_t nao_model_int8[];
extern "C" const std::uint8_t nao_model_int8_end[];
extern "C" const std::uint8_t nao_model_packed[];
extern "C" const std::uint8_t nao_model_packed_end[];

namespace nao::compiled {

static_assert(kFormatVersion == kModelFormatVersion, "the generated config is of another model.bin format");
static_assert(kNumTensors == detail::policyViewCount<Dims>(kChunk), "the generated tensor table is not the manifest's");
static_assert(kChunk >= 1 && kChunk <= kPolicyMaxChunk,
              "the compiled-in model's head is beyond the runtime's");
static_assert(kJointNames.size() == static_cast<std::size_t>(kTokens), "one joint per token");

ModelBytes modelBytes() {
  return {nao_model_blob, static_cast<std::size_t>(nao_model_blob_end - nao_model_blob)};
}

namespace {

ModelHeader makeHeader() {
  ModelHeader h;
  h.arch = Dims::arch();
  h.arch.movements = kMovements;
  h.arch.clusters = kClusters;
  h.arch.max_steps = kMaxSteps;
  h.arch.chunk = kChunk;
  h.conditioning = kConditioning;
  for (std::size_t j = 0; j < kJointNames.size(); ++j)
    h.joints.push_back({std::string(kJointNames[j]), kJointLower[j], kJointUpper[j], kJointVelocity[j]});
  for (const std::string_view m : kMovementNames) h.movement_names.emplace_back(m);
  h.metadata_json = std::string(kMetadataJson);
  return h;
}

const ModelHeader& compiledHeader() {
  static const ModelHeader header = makeHeader();
  return header;
}

}  // namespace

ModelImage modelImage() {
  const ModelHeader& header = compiledHeader();
  const ModelBytes b = modelBytes();
  ModelImage image{b.data, b.size, kChecksum, &header, kTensorOffsets.data(), kTensorExtents.data(), kTensorOffsets.size()};
  if constexpr (kInt8Weights) {
    image.int8_bytes = nao_model_int8;
    image.int8_size = static_cast<std::size_t>(nao_model_int8_end - nao_model_int8);
    image.int8_checksum = kInt8Checksum;
  }
  if constexpr (kPackedWeights) {
    image.packed_bytes = nao_model_packed;
    image.packed_size = static_cast<std::size_t>(nao_model_packed_end - nao_model_packed);
    image.packed_checksum = kPackedChecksum;
  }
  return image;
}

static_assert(!kInt8Weights || kInt8Bytes == quantizedPolicyBytes<Dims>(), "the generated int8 blob is not the layout's");
static_assert(!kPackedWeights || kPackedBytes == packedPolicyBytes<Dims>(), "the generated packed blob is not the layout's");

PolicyWeights<Dims> policyWeights() noexcept {
  PolicyWeights<Dims> w = bindPolicyWeightsAt<Dims>(nao_model_blob, kTensorOffsets.data(), kTensorExtents.data(),
                                                   compiledHeader().arch, kConditioning);
  if constexpr (kInt8Weights) bindQuantizedWeights<Dims>(w, nao_model_int8);
  if constexpr (kPackedWeights) bindPackedWeights<Dims>(w, nao_model_packed);
  return w;
}

}  // namespace nao::compiled
