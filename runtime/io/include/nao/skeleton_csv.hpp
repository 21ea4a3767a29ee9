// Skeleton CSV: a 3D human skeleton sequence, one row per sample (docs/formats.md). nao_rt reads
// it as a recorded reference (--reference file:PATH); the toolchain's triangulation and
// synthesiser write it. Configure-time code.
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

namespace nao {

/// Header line of the skeleton columns (no trailing newline).
std::string skeletonCsvHeader();

/// Writes one frame's skeleton columns (no trailing newline). Missing points are written as
/// 0,0,0,0 so a reader can never mistake them for data.
void writeSkeletonColumns(std::ostream& out, const SkeletonFrame& frame);

/// Writes a whole skeleton CSV. With `with_views`, after the skeleton columns every point's
/// <Name>_cams (bitmask of the cameras its fit used, bit c = camera c; 0 = not measured) and
/// <Name>_px (their RMS reprojection error, px; 0 = not measured). `digits`: significant digits
/// of times and positions, 10 (triangulate's files, 0.1 nm at 1 m) or 17 (readSkeletonCsv gives
/// back the frames bit for bit, so a run on the file is the run on the frames). Throws InputError
/// if the file cannot be written.
void writeSkeletonCsv(const std::string& path, const Skeleton& frames, bool with_views = false, int digits = 10);

/// Reads a skeleton CSV (`_ok` = 2 sets SkeletonFrame::interpolated). Throws InputError naming the file, line and problem for a missing
/// column, a short row, a non-numeric or non-finite value, or time stamps that decrease.
Skeleton readSkeletonCsv(const std::string& path);

}  // namespace nao
