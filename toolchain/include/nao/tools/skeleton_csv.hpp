// Skeleton CSV: a 3D human skeleton sequence, one row per sample (docs/formats.md).
//
// Columns: t_s, then for every point of kSkeletonPointNames: <Name>_x, <Name>_y, <Name>_z
// (m, world frame) and <Name>_ok (1 = valid, 2 = valid but interpolated across a short gap,
// 0 = missing). Further columns are allowed and ignored by the reader (truth.csv appends joint
// angles this way; triangulate appends <Name>_cams and <Name>_px after all points).
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

/// Writes a whole skeleton CSV. With `with_views`, after the skeleton columns every point's
/// <Name>_cams (bitmask of the cameras its fit used, bit c = camera c; 0 = not measured) and
/// <Name>_px (their RMS reprojection error, px; 0 = not measured). Throws UserError if the
/// file cannot be written.
void writeSkeletonCsv(const std::string& path, const Skeleton& frames, bool with_views = false);

/// Reads a skeleton CSV (`_ok` = 2 sets SkeletonFrame::interpolated). Throws UserError naming the file, line and problem for a missing
/// column, a short row, a non-numeric or non-finite value, or time stamps that decrease.
Skeleton readSkeletonCsv(const std::string& path);

}  // namespace nao::tools
