// The skeleton CSV is the runtime's input format (nao/skeleton_csv.hpp); the toolchain writes it.
#pragma once

#include "nao/skeleton_csv.hpp"

namespace nao::tools {
using nao::readSkeletonCsv;
using nao::Skeleton;
using nao::skeletonCsvHeader;
using nao::writeSkeletonColumns;
using nao::writeSkeletonCsv;
}  // namespace nao::tools
