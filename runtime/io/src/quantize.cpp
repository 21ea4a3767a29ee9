// The int8 and packed fp32 blobs of a model (nao/quantize.hpp).
#include "nao/quantize.hpp"

#include "nao/policy.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace nao {

const char* weightPrecisionName(WeightPrecision p) noexcept {
  switch (p) {
    case WeightPrecision::kInt8:
      return "int8";
    case WeightPrecision::kFp32Packed:
      return "fp32-packed";
    case WeightPrecision::kFp32:
      break;
  }
  return "fp32";
}

WeightPrecision parseWeightPrecision(const std::string& s) {
  if (s == "fp32") return WeightPrecision::kFp32;
  if (s == "int8") return WeightPrecision::kInt8;
  if (s == "fp32-packed") return WeightPrecision::kFp32Packed;
  throw std::invalid_argument("precision must be fp32, fp32-packed or int8, got '" + s + "'");
}

WeightPrecision runPrecision(const std::string& asked, bool compiled_in, const ModelImage& image) {
  if (!asked.empty()) return parseWeightPrecision(asked);
  if (compiled_in && image.int8_bytes != nullptr) return WeightPrecision::kInt8;
  if (compiled_in && image.packed_bytes != nullptr) return WeightPrecision::kFp32Packed;
  return WeightPrecision::kFp32;
}

namespace {

/// Σ bytes(out, in) over the matrices the int8 and packed blobs hold (attention projections and
/// FFN weights of every layer), from the dimensions alone.
template <class Bytes>
std::size_t sumOverMatrices(const PolicyArch& arch, Bytes bytes) {
  const auto d = static_cast<std::size_t>(arch.d_model);
  std::size_t ffn = 0, in = d;
  for (const int h : arch.ffn_hidden) {
    ffn += bytes(static_cast<std::size_t>(h), in);
    in = static_cast<std::size_t>(h);
  }
  ffn += bytes(d, in);
  const std::size_t attention = 4 * bytes(d, d);
  return static_cast<std::size_t>(arch.encoder_layers) * (attention + ffn) +
         static_cast<std::size_t>(arch.decoder_layers) * (2 * attention + ffn);
}

/// A blob of `size` bytes (64-byte aligned, zero where nothing is written): for each
/// TensorRole::kMatrix tensor, in manifest order, `section(spec, out, in)` checks its shape and
/// gives its bytes, and `write(W, out, in, dst)` fills them. `who` names the caller in the layout
/// errors.
template <class Section, class Write>
AlignedBytes buildBlob(const ModelFile& model, std::size_t size, const char* who, Section section, Write write) {
  AlignedBytes blob = AlignedBytes::allocate(size);
  std::fill(blob.data.get(), blob.data.get() + blob.size, std::uint8_t{0});
  std::size_t off = 0;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) {
    const TensorSpec& t = model.tensors[i].spec;
    if (t.role != TensorRole::kMatrix) continue;
    const int in = t.shape[0], out = t.shape[1];  // model.bin matrices are [in, out] row-major
    const std::size_t bytes = section(t, out, in);
    if (off + bytes > blob.size) throw std::logic_error(std::string(who) + ": the manifest's matrices exceed the layout");
    write(model.data(i), out, in, blob.data.get() + off);
    off += bytes;
  }
  if (off != blob.size) throw std::logic_error(std::string(who) + ": the manifest's matrices do not fill the layout");
  return blob;
}

/// A compiled-in blob: present, `want` bytes, its FNV-1a 64 the generated one. `what` names it in
/// "no <what> weights were compiled in", `short_what` in the size and checksum messages.
void checkCompiledBlob(const std::uint8_t* bytes, std::size_t size, std::uint64_t checksum, std::size_t want,
                       const char* what, const char* short_what, const std::string& origin) {
  if (bytes == nullptr) throw ModelFileError(origin + ": no " + what + " weights were compiled in");
  if (size != want)
    throw ModelFileError(origin + ": the compiled-in " + short_what + " weights are " + std::to_string(size) +
                         " bytes, the architecture needs " + std::to_string(want));
  if (quantizedChecksum(bytes, size) != checksum)
    throw ModelFileError(origin + ": " + short_what + " weights checksum mismatch (not the bytes its generated code describes)");
}

}  // namespace

void quantizeMatrixInt8(const float* W, int out, int in, std::uint8_t* section) {
  if (in % 2 != 0 || in > detail::kInt8MaxIn || out <= 0 || in <= 0)
    throw std::invalid_argument("quantizeMatrixInt8: " + std::to_string(out) + " x " + std::to_string(in) +
                                " (the int8 layout takes an even number of inputs up to 512)");
  auto* q = reinterpret_cast<std::int8_t*>(section);
  float* scale = reinterpret_cast<float*>(section + detail::quantPad(static_cast<std::size_t>(out) * in));
  for (int r = 0; r < out; ++r) {
    float m = 0.0f;
    for (int k = 0; k < in; ++k) m = std::max(m, std::fabs(W[static_cast<std::size_t>(k) * out + r]));
    const float s = m / 127.0f;
    for (int k = 0; k < in; ++k) {
      const float v = s > 0.0f ? std::nearbyint(W[static_cast<std::size_t>(k) * out + r] / s) : 0.0f;
      q[(static_cast<std::size_t>(k / 2) * out + r) * 2 + k % 2] = static_cast<std::int8_t>(std::clamp(v, -127.0f, 127.0f));
    }
    std::memcpy(scale + r, &s, sizeof(float));
  }
}

std::size_t quantizedModelBytes(const PolicyArch& arch) {
  // From the dimensions, without the manifest (no allocation: checkInt8Image runs at start-up);
  // quantizeModelInt8 walks the manifest and checks that it comes to the same size.
  return sumOverMatrices(arch, detail::quantSectionBytes);
}

AlignedBytes quantizeModelInt8(const ModelFile& model) {
  // The per-head slices of Wo start at pairs of columns: the head size must be even too.
  const PolicyArch& arch = model.header.arch;
  if (arch.heads <= 0 || (arch.d_model / arch.heads) % 2 != 0)
    throw ModelFileError("int8 weights: head size " + std::to_string(arch.heads > 0 ? arch.d_model / arch.heads : 0) +
                         " is odd (the int8 kernels take input columns in pairs)");
  return buildBlob(model, quantizedModelBytes(arch), "quantizeModelInt8", [](const TensorSpec& t, int out, int in) {
    if (in % 2 != 0 || in > detail::kInt8MaxIn)
      throw ModelFileError("int8 weights: " + t.name + " has " + std::to_string(in) +
                           " inputs (the int8 kernels take an even number up to " +
                           std::to_string(detail::kInt8MaxIn) + ")");
    return detail::quantSectionBytes(static_cast<std::size_t>(out), static_cast<std::size_t>(in));
  }, [](const float* W, int out, int in, std::uint8_t* dst) { quantizeMatrixInt8(W, out, in, dst); });
}

void packMatrixFp32(const float* W, int out, int in, float* P) {
  if (out <= 0 || in <= 0 || !detail::packedShape(out, in))
    throw std::invalid_argument("packMatrixFp32: " + std::to_string(out) + " x " + std::to_string(in) +
                                " (the packed layout takes outputs in multiples of " +
                                std::to_string(detail::kPackBlock) + " and inputs in multiples of " +
                                std::to_string(detail::kPackStrip) + ")");
  constexpr int S = detail::kPackStrip, B = detail::kPackBlock;
  std::size_t i = 0;
  for (int k0 = 0; k0 < in; k0 += S)
    for (int r0 = 0; r0 < out; r0 += B)
      for (int k = k0; k < k0 + S; ++k)
        for (int r = r0; r < r0 + B; ++r) P[i++] = W[static_cast<std::size_t>(k) * out + r];
}

std::size_t packedModelBytes(const PolicyArch& arch) {
  return sumOverMatrices(arch, [](std::size_t out, std::size_t in) { return sizeof(float) * out * in; });
}

AlignedBytes packModelFp32(const ModelFile& model) {
  return buildBlob(model, packedModelBytes(model.header.arch), "packModelFp32", [](const TensorSpec& t, int out, int in) {
    if (!detail::packedShape(out, in))
      throw ModelFileError("packed fp32 weights: " + t.name + " is " + std::to_string(out) + " x " +
                           std::to_string(in) + " (the packed layout takes outputs in multiples of " +
                           std::to_string(detail::kPackBlock) + " and inputs in multiples of " +
                           std::to_string(detail::kPackStrip) + ")");
    return sizeof(float) * static_cast<std::size_t>(out) * static_cast<std::size_t>(in);
  }, [](const float* W, int out, int in, std::uint8_t* dst) { packMatrixFp32(W, out, in, reinterpret_cast<float*>(dst)); });
}

std::uint64_t quantizedChecksum(const std::uint8_t* data, std::size_t size) noexcept { return fnv1a64(data, size); }

void checkInt8Image(const ModelImage& image, const PolicyArch& arch, const std::string& origin) {
  checkCompiledBlob(image.int8_bytes, image.int8_size, image.int8_checksum, quantizedModelBytes(arch), "int8", "int8",
                    origin);
}

void checkPackedImage(const ModelImage& image, const PolicyArch& arch, const std::string& origin) {
  checkCompiledBlob(image.packed_bytes, image.packed_size, image.packed_checksum, packedModelBytes(arch),
                    "packed fp32", "packed", origin);
}

AlignedBytes anonymousCopy(const std::uint8_t* image_bytes, std::size_t size) {
  AlignedBytes copy = AlignedBytes::allocate(size);
  // A MiB at a time, each part's image pages released once copied: the blob and its copy are
  // never resident together (peak RSS as reading the blob in place).
  constexpr std::size_t kPart = std::size_t{1} << 20;
  for (std::size_t off = 0; off < size; off += kPart) {
    const std::size_t n = std::min(kPart, size - off);
    std::memcpy(copy.data.get() + off, image_bytes + off, n);
    releaseImagePages(image_bytes + off, n);
  }
  releaseImagePages(image_bytes, size);  // the pages straddling two parts
  return copy;
}

}  // namespace nao
