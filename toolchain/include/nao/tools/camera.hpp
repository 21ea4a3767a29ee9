// The camera model lives in the runtime (nao/camera.hpp: the live camera source uses it too);
// the toolchain names it in its own namespace.
#pragma once

#include "nao/camera.hpp"

namespace nao::tools {

using nao::Camera;
using nao::CameraSet;
using nao::distort;
using nao::project;
using nao::toCamera;

}  // namespace nao::tools
