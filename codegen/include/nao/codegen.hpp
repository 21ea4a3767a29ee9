// nao_codegen: turns a checked model.bin into the sources that compile it into nao_rt
// (docs/policy.md "codegen and binding"): a constexpr config header, a header with the
// PolicyDims alias, and an assembler file that .incbin's a copy of the model into .rodata.
// Build-time code: allocates, throws, does I/O.
#pragma once

#include "nao/model_file.hpp"
#include "nao/quantize.hpp"

#include <string>
#include <vector>

namespace nao::codegen {

inline constexpr const char* kConfigHeader = "nao_model_config.hpp";
inline constexpr const char* kDimsHeader = "nao_model_dims.hpp";
inline constexpr const char* kWeightsAsm = "nao_model_weights.S";
inline constexpr const char* kModelCopy = "model.bin";
/// Symbols of the embedded bytes (first byte, one past the last), 64-byte aligned.
inline constexpr const char* kBlobSymbol = "nao_model_blob";
inline constexpr const char* kBlobEndSymbol = "nao_model_blob_end";
inline constexpr const char* kInt8Copy = "model.int8";  ///< --precision int8: the int8 blob
inline constexpr const char* kInt8Symbol = "nao_model_int8";
inline constexpr const char* kInt8EndSymbol = "nao_model_int8_end";
inline constexpr const char* kPackedCopy = "model.packed";  ///< --precision fp32-packed: the packed blob
inline constexpr const char* kPackedSymbol = "nao_model_packed";
inline constexpr const char* kPackedEndSymbol = "nao_model_packed_end";

/// One compile-time dimension of the policy as the generated code states it.
struct ArchConstant {
  std::string name;                   ///< the constant in namespace nao::compiled, e.g. "kWindow"
  int value = 0;
  bool policy_dims_argument = false;  ///< passed to nao::PolicyDims (in archConstants' order)
};

/// Every compile-time dimension of `arch`, in the generated config's order: the one place that
/// says how a PolicyArch becomes code. configHeader emits each as `inline constexpr int`, and
/// dimsHeader passes the marked ones, in this order, as nao::PolicyDims' template arguments
/// (which follow PolicyDims' own parameter order). A new PolicyArch field is one entry here.
std::vector<ArchConstant> archConstants(const PolicyArch& arch);

/// nao_model_config.hpp for `model`: namespace nao::compiled, every dimension, the
/// conditioning, checksum, parameter count, tensor names/offsets/counts in manifest order,
/// joint names and limits, movement names. `source` is named in the banner comment only.
/// `int8` (nullptr: fp32) is the model's int8 blob (quantizeModelInt8): kInt8Weights, its size
/// and checksum; `packed` (nullptr: none) the packed fp32 blob (packModelFp32): kPackedWeights,
/// its size and checksum.
std::string configHeader(const ModelFile& model, const std::string& source, const AlignedBytes* int8 = nullptr,
                         const AlignedBytes* packed = nullptr);

/// nao_model_dims.hpp: `using Dims = nao::PolicyDims<...>` (needs nao/policy.hpp and
/// exactly three FFN widths; otherwise a header that fails with #error when included).
std::string dimsHeader(const ModelFile& model);

/// nao_model_weights.S: `.incbin` of `blob_path` (absolute) into .rodata, 64-byte aligned,
/// between kBlobSymbol and kBlobEndSymbol; `int8_path` (empty: fp32, nothing) likewise between
/// kInt8Symbol and kInt8EndSymbol, `packed_path` between kPackedSymbol and kPackedEndSymbol (all
/// symbols exist either way).
std::string weightsAsm(const ModelFile& model, const std::string& blob_path, const std::string& int8_path = {},
                       const std::string& packed_path = {});

/// Writes `content` to `path` unless the file already holds exactly that (temporary file +
/// rename). Returns whether it wrote. Throws std::runtime_error naming the path.
bool writeIfChanged(const std::string& path, const std::string& content);

struct Result {
  ModelFile model;
  std::vector<std::string> written;    ///< paths whose content changed
  std::vector<std::string> unchanged;  ///< paths left as they were
};

/// readModelFile(model_path) (throws ModelFileError), then writes the three sources and the
/// model copy into `out_dir` (created if missing), each only if its content changed.
Result generate(const std::string& model_path, const std::string& out_dir,
                WeightPrecision precision = WeightPrecision::kFp32);

}  // namespace nao::codegen
