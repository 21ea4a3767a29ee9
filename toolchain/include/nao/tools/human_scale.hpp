// The human scale of a demonstration is computed by the runtime's nao/human_scale.hpp.
#pragma once

#include "nao/human_scale.hpp"

namespace nao::tools {
using nao::estimateHumanArmLengths;
using nao::HumanArmLengths;
using nao::withDemoScale;
}  // namespace nao::tools
