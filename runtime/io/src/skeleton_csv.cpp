#include "nao/skeleton_csv.hpp"

#include "nao/csv_reader.hpp"
#include "nao/file_io.hpp"
#include "nao/input_error.hpp"

#include <cmath>
#include <sstream>

namespace nao {

std::string skeletonCsvHeader() {
  std::string h = "t_s";
  for (const char* name : kSkeletonPointNames)
    for (const char* suffix : {"_x", "_y", "_z", "_ok"}) h += std::string(",") + name + suffix;
  return h;
}

void writeSkeletonColumns(std::ostream& out, const SkeletonFrame& frame) {
  out << frame.t_s;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    if (frame.ok[i])
      out << ',' << frame.p_W[i].x() << ',' << frame.p_W[i].y() << ',' << frame.p_W[i].z()
          << (frame.interpolated[i] ? ",2" : ",1");
    else
      out << ",0,0,0,0";
  }
}

void writeSkeletonCsv(const std::string& path, const Skeleton& frames, bool with_views, int digits) {
  std::ostringstream out;
  out.precision(digits);
  out << skeletonCsvHeader();
  if (with_views) {
    for (const char* name : kSkeletonPointNames) out << ',' << name << "_cams";
    for (const char* name : kSkeletonPointNames) out << ',' << name << "_px";
  }
  out << '\n';
  for (const SkeletonFrame& f : frames) {
    writeSkeletonColumns(out, f);
    if (with_views) {
      for (int i = 0; i < kNumSkeletonPoints; ++i) out << ',' << (f.ok[i] ? f.views[i] : 0u);
      for (int i = 0; i < kNumSkeletonPoints; ++i) out << ',' << (f.ok[i] ? std::round(1000.0 * f.reprojection_px[i]) / 1000.0 : 0.0);
    }
    out << '\n';
  }
  // Whole or not at all: a reader never sees half a skeleton.
  const std::string text = out.str();
  if (const std::string problem = writeFileAtomically(path, text.data(), text.size()); !problem.empty())
    throw InputError("cannot write " + path + ": " + problem);
}

Skeleton readSkeletonCsv(const std::string& path) {
  CsvReader csv(path, "skeleton CSV");
  const std::size_t c_t = csv.column("t_s");
  std::array<std::array<std::size_t, 4>, kNumSkeletonPoints> c_pt;
  for (int i = 0; i < kNumSkeletonPoints; ++i)
    for (int k = 0; k < 4; ++k)
      c_pt[i][k] = csv.column(std::string(kSkeletonPointNames[i]) + std::array<const char*, 4>{"_x", "_y", "_z", "_ok"}[k]);

  Skeleton frames;
  while (csv.next()) {
    if (csv.cells() < csv.columns())
      throw InputError(csv.where() + ": " + std::to_string(csv.cells()) + " values, expected " +
                      std::to_string(csv.columns()));
    SkeletonFrame f;
    f.t_s = csv.number(c_t);
    if (!frames.empty() && f.t_s <= frames.back().t_s)
      throw InputError(csv.where() + ": time t_s=" + std::to_string(f.t_s) + " does not increase");
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      const double ok = csv.number(c_pt[i][3]);
      f.ok[i] = ok != 0.0;
      f.interpolated[i] = ok == 2.0;
      f.p_W[i] = f.ok[i] ? Eigen::Vector3d(csv.number(c_pt[i][0]), csv.number(c_pt[i][1]), csv.number(c_pt[i][2]))
                         : Eigen::Vector3d::Zero();
    }
    frames.push_back(f);
  }
  return frames;
}

}  // namespace nao
