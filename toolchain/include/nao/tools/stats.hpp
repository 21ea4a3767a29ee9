// Small order statistics shared by the toolchain's summaries (the runtime's nao/median.hpp).
#pragma once

#include "nao/median.hpp"

namespace nao::tools {
using nao::median;
}  // namespace nao::tools
