// readModelSpec of a bare metadata text: the header a test would otherwise build by hand.
#pragma once

#include "nao/model_file.hpp"

#include <string>
#include <vector>

namespace nao::test {

/// readModelSpec (default retargeting) of a header with `metadata`, `movements` and `d_model`.
inline ModelSpec specOf(const std::string& metadata, const std::vector<std::string>& movements, int d_model,
                        const std::string& origin) {
  ModelHeader h;
  h.metadata_json = metadata;
  h.movement_names = movements;
  h.arch.d_model = d_model;
  return readModelSpec(h, RetargetParams{}, origin);
}

}  // namespace nao::test
