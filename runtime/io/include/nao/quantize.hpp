// Reduced-precision weights (docs/policy.md "int8 weights"): the int8 blob of a model.bin.
//
// Every matrix of role TensorRole::kMatrix in the manifest (policy_config.hpp: the attention
// projections wq, wk, wv, wo and the FFN weights), in manifest order, is stored as int8 with one
// float scale per output row (max |row| / 127), its input columns interleaved in pairs
// (policy_kernels.hpp "Reduced precision": the pmaddwd kernels read one pair per int32 lane, the
// pmaddubsw/vpdpbusd ones the lines of two pairs interleaved into a row's four inputs). ±127: any
// weight byte keeps pmaddubsw's pair sums of 7-bit tokens exact. Biases, layer norms, embeddings,
// the head, the normalisation and the centroids stay fp32. The blob is a pure function of the
// model's fp32 tensors: nao_codegen --precision int8 writes it next to the compiled-in model and
// nao_rt --weights FILE --precision int8 makes the same bytes at start-up.
//
// The packed fp32 blob (docs/policy.md "Packed fp32 weights") holds the same matrices in fp32,
// each in the kernels' block order (policy_kernels.hpp "Packed fp32"): the same bits as the
// model's own matrices, read in address order. nao_codegen --precision fp32-packed compiles it
// in; nao_rt --precision fp32-packed makes it at start-up otherwise.
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace nao {

/// fp32: the reference. int8: the matrices above in int8 (fp32 everything else). fp32-packed:
/// fp32 with the same matrices also in the kernels' block order (policy_kernels.hpp "Packed
/// fp32"): the same bits as fp32, read in address order.
enum class WeightPrecision : int { kFp32 = 0, kInt8 = 1, kFp32Packed = 2 };

/// "fp32", "int8" or "fp32-packed".
const char* weightPrecisionName(WeightPrecision p) noexcept;

/// Parses "fp32" / "int8" / "fp32-packed"; throws std::invalid_argument naming the accepted
/// values otherwise.
WeightPrecision parseWeightPrecision(const std::string& s);

/// The precision a run uses: `asked` ("fp32"/"int8"/"fp32-packed") if given, else for the
/// compiled-in model (`compiled_in`) the blob `image` carries (int8 or fp32-packed: nao_codegen
/// --precision), else fp32. nao_rt's run and --info both decide it here. Throws as parseWeightPrecision.
WeightPrecision runPrecision(const std::string& asked, bool compiled_in, const ModelImage& image);

/// Quantises one matrix into its blob section (detail::quantSectionBytes(out, in) bytes):
/// byte (p·out + r)·2 + e = round(W(r, 2p + e) / s(r)), clamped to ±127, then out floats
/// s(r) = max_k |W(r, k)| / 127 at quantPad(out·in). W is column-major [out, in] (model.bin's
/// row-major [in, out]); in must be even.
void quantizeMatrixInt8(const float* W, int out, int in, std::uint8_t* section);

/// Bytes of the int8 blob of a model with this architecture.
std::size_t quantizedModelBytes(const PolicyArch& arch);

/// 64-byte aligned bytes owned by a run (the --weights int8 blob).
struct AlignedBytes {
  struct Free {
    void operator()(std::uint8_t* p) const noexcept { ::operator delete[](p, std::align_val_t{64}); }
  };
  std::unique_ptr<std::uint8_t[], Free> data;
  std::size_t size = 0;

  /// `size` bytes, 64-byte aligned, uninitialised. Configure time: allocates.
  static AlignedBytes allocate(std::size_t size) {
    AlignedBytes b;
    b.data.reset(static_cast<std::uint8_t*>(::operator new[](size, std::align_val_t{64})));
    b.size = size;
    return b;
  }
};

/// `size` bytes of a compiled-in blob (the int8 or packed copy in .rodata) copied into
/// anonymous memory, and the blob's whole pages handed back (releaseImagePages): the bytes a
/// run reads every tick then live in memory of its own, not in the binary's file pages, whose
/// cost to walk depends on how the file came to be cached. Measured on the test VMs: a freshly
/// linked nao_rt's page-cache pages made every fifth warming of the 24 MB packed copy take
/// ~25 ms instead of 1-3 ms (and its answers miss LoLA's 12 ms cycle); the same binary copied,
/// or these bytes in anonymous memory, never did. Configure time: allocates.
AlignedBytes anonymousCopy(const std::uint8_t* image_bytes, std::size_t size);

/// The int8 blob of `model` (quantizedModelBytes(arch) bytes, padding zero). Configure time:
/// allocates. Throws ModelFileError if a matrix has an odd input size or more than 512 inputs
/// (the kernels' exact int32 range).
AlignedBytes quantizeModelInt8(const ModelFile& model);

/// The int8 blob made from bound fp32 views (quantizeMatrixInt8 on each, visitQuantViews
/// order): the same bytes as quantizeModelInt8 of the file the views came from
/// (tests/test_policy_int8.cpp). Configure time: allocates.
template <class Dims>
AlignedBytes quantizePolicyInt8(PolicyWeights<Dims> w) {
  AlignedBytes blob = AlignedBytes::allocate(quantizedPolicyBytes<Dims>());
  std::fill(blob.data.get(), blob.data.get() + blob.size, std::uint8_t{0});
  std::size_t off = 0;
  detail::visitQuantViews(w, [&](const auto& view, auto&) {
    using V = std::remove_reference_t<decltype(view)>;
    constexpr int out = V::RowsAtCompileTime, in = V::ColsAtCompileTime;
    quantizeMatrixInt8(view.data(), out, in, blob.data.get() + off);
    off += detail::quantSectionBytes(out, in);
  });
  return blob;
}

/// Packs one matrix (W column-major [out, in], model.bin's row-major [in, out]) into P
/// (out·in floats): P[((s·out/32 + b)·16 + c)·32 + i] = W(32b + i, 16s + c). Throws
/// std::invalid_argument unless out is a multiple of 32 and in of 16.
void packMatrixFp32(const float* W, int out, int in, float* P);

/// Bytes of the packed fp32 blob of a model with this architecture (packedPolicyBytes).
std::size_t packedModelBytes(const PolicyArch& arch);

/// The packed fp32 blob of `model`: the manifest's TensorRole::kMatrix tensors, in its order, each
/// packed (packMatrixFp32). Configure time: allocates. Throws ModelFileError naming a matrix of a
/// shape the layout does not take.
AlignedBytes packModelFp32(const ModelFile& model);

/// The packed fp32 blob made from bound fp32 views (packMatrixFp32 on each, visitQuantViews
/// order): the same bytes as packModelFp32 of the file the views came from
/// (tests/test_policy_packed.cpp). Configure time: allocates.
template <class Dims>
AlignedBytes packPolicyFp32(PolicyWeights<Dims> w) {
  static_assert(packedSupported<Dims>(), "packPolicyFp32: a matrix of this architecture has no packed layout");
  AlignedBytes blob = AlignedBytes::allocate(packedPolicyBytes<Dims>());
  std::size_t off = 0;
  detail::visitQuantViews(w, [&](const auto& view, auto&) {
    using V = std::remove_reference_t<decltype(view)>;
    constexpr int out = V::RowsAtCompileTime, in = V::ColsAtCompileTime;
    packMatrixFp32(view.data(), out, in, reinterpret_cast<float*>(blob.data.get() + off));
    off += sizeof(float) * static_cast<std::size_t>(out) * in;
  });
  if (off != blob.size) throw std::logic_error("packPolicyFp32: the views do not fill packedPolicyBytes");
  return blob;
}

/// FNV-1a 64 of a blob (what the generated code states about the compiled-in one).
std::uint64_t quantizedChecksum(const std::uint8_t* data, std::size_t size) noexcept;

/// Checks the compiled-in int8 blob of `image` (nao_codegen --precision int8) once: present, of
/// the architecture's size (quantizedModelBytes of `arch`), and its FNV-1a 64 equal to the
/// generated one. Throws ModelFileError "<origin>: <problem>". No allocation unless it throws.
void checkInt8Image(const ModelImage& image, const PolicyArch& arch, const std::string& origin);

/// checkInt8Image for the compiled-in packed fp32 blob (nao_codegen --precision fp32-packed):
/// present, packedModelBytes(arch) long, its FNV-1a 64 the generated one.
void checkPackedImage(const ModelImage& image, const PolicyArch& arch, const std::string& origin);

}  // namespace nao
