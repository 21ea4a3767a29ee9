// What a model.bin's metadata JSON tells a run beyond the tensors (DESIGN §8, "model.bin is
// self-sufficient"): the retargeting setting its data was made with. The law the runtime adds is
// a manifest tensor (law.gain); the autonomous starts are model_file.hpp's (modelStarts).
// Configure-time code: parses JSON, allocates, throws.
#pragma once

#include "nao/retarget.hpp"

#include <string>
#include <vector>

namespace nao {

/// `defaults` with the retargeting setting a model's metadata records (data.retarget: priority,
/// lambda_q, posture_weights) applied; unchanged when the metadata has none. Throws
/// std::runtime_error naming `origin` for a setting that is present but unusable.
RetargetParams modelRetargetSetting(const std::string& metadata_json, const RetargetParams& defaults,
                                    const std::string& origin);

}  // namespace nao
