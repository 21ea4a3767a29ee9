// The one decoding of model.bin's metadata JSON (nao_io internal): parsed once by readModelSpec,
// each section decoded from the parsed text.
#pragma once

#include "nao/model_file.hpp"
#include "nao/model_spec.hpp"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace nao::detail {

using MetadataJson = nlohmann::ordered_json;

/// The metadata parsed; a text that is not JSON gives a discarded value (no section is present).
inline MetadataJson parseModelMetadata(const std::string& metadata_json) {
  return MetadataJson::parse(metadata_json, nullptr, /*allow_exceptions=*/false);
}

ModelStarts startsFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names,
                               const std::string& origin);
std::vector<ModelWorkspace> workspaceFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names,
                                                  const std::string& origin);
std::vector<ModelRunCodes> runCodesFromMetadata(const MetadataJson& j, const std::vector<std::string>& movement_names,
                                                int d_model, const std::string& origin);
RetargetParams retargetFromMetadata(const MetadataJson& j, const RetargetParams& defaults, const std::string& origin);

}  // namespace nao::detail
