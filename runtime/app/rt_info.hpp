// `nao_rt --info`: describes a model (the compiled-in one or --weights FILE) as one JSON
// object after checking it like start-up does (model.bin validation, joints against the URDF).
// Configure-time code: allocates, reads files.
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy_kernels.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <optional>
#include <string>

namespace nao::rt {

struct InfoOptions {
  std::string weights_path;                 ///< model.bin to describe; empty: the compiled-in model
  std::string urdf_path;                    ///< the URDF the joints must match
  ModelImage compiled;                      ///< the compiled-in model (bytes nullptr if the build has none)
  std::string precision;                    ///< --precision; empty: what a run would default to
  /// The kernel a run with the same options binds its weights with (summary.json model.kernel).
  PolicyKernel kernel = bestPolicyKernel();
  /// Whether this nao_rt computes an architecture's step (its compiled dimensions); empty: unknown.
  std::function<bool(const PolicyArch&)> computes;
};

/// The JSON description of a checked model (pretty-printed, no trailing newline): format_version,
/// dimensions, conditioning, movements, parameters, checksum ("0x%016x"), weights ("compiled" or
/// "file"), precision ("fp32", "fp32-packed" or "int8": what a run with the same options uses),
/// kernel (the one a run with the same options binds the weights with), tensors,
/// joints, starts (per movement, the autonomous starts' name and ticks; empty lists without
/// any), metadata (parsed JSON if it parses, else the string), source. Throws ModelFileError for
/// unusable starts. `runs`, when known: whether this nao_rt runs the model (its compiled
/// dimensions compute the model's step), the last key.
std::string modelInfoJson(const ModelFile& model, const std::string& source, const std::string& precision = "fp32",
                          PolicyKernel kernel = bestPolicyKernel(), std::optional<bool> runs = std::nullopt);

/// Checks the model and prints modelInfoJson + newline on `out`: returns 0. On any problem
/// (no model, a bad file, joints that differ from the URDF, an unusable URDF) prints exactly
/// one line "nao_rt: <message>" on `err` and returns 1.
int runInfo(const InfoOptions& options, std::ostream& out, std::ostream& err);

}  // namespace nao::rt
