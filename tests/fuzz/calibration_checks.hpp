// What an accepted calibration promises (shared by the JSON and TOML fuzz targets).
#pragma once

#include "fuzz_util.hpp"

#include "nao/tools/camera.hpp"

#include <Eigen/Core>

namespace nao::fuzz {

inline void checkCameras(const tools::CameraSet& cams) {
  NAO_FUZZ_CHECK(!cams.empty());
  for (const tools::Camera& c : cams) {
    NAO_FUZZ_CHECK(c.width >= 1 && c.height >= 1);
    NAO_FUZZ_CHECK(c.K.allFinite() && c.K(0, 0) >= 1.0 && c.K(1, 1) >= 1.0);
    NAO_FUZZ_CHECK(c.dist.allFinite() && c.p_CW.allFinite());
    NAO_FUZZ_CHECK(c.R_CW.allFinite());
    NAO_FUZZ_CHECK((c.R_CW.transpose() * c.R_CW - Eigen::Matrix3d::Identity()).norm() < 1e-5);
  }
}

}  // namespace nao::fuzz
