// Skeleton CSV: a 3D human skeleton sequence, one row per sample (docs/formats.md).
//
// Columns: t_s, then for every point of kSkeletonPointNames: <Name>_x, <Name>_y, <Name>_z
// (m, world frame) and <Name>_ok (1 = valid, 0 = missing). Further columns are allowed and
// ignored by the reader (truth.csv appends joint angles this way).
#pragma once

#include "nao/body25.hpp"

#include <iosfwd>
#include <string>
#include <vector>

namespace nao::tools {

using Skeleton = std::vector<SkeletonFrame>;

/// Header line of the skeleton columns (no trailing newline).
std::string skeletonCsvHeader();

/// Writes one frame's skeleton columns (no trailing newline). Missing points are written as
/// 0,0,0,0 so a reader can never mistake them for data.
void writeSkeletonColumns(std::ostream& out, const SkeletonFrame& frame);

/// Writes a whole skeleton CSV. Throws UserError if the file cannot be written.
void writeSkeletonCsv(const std::string& path, const Skeleton& frames);

/// Reads a skeleton CSV. Throws UserError naming the file, line and problem for a missing
/// column, a short row, a non-numeric or non-finite value, or time stamps that decrease.
Skeleton readSkeletonCsv(const std::string& path);

}  // namespace nao::tools
