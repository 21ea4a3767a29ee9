#include "nao/tools/skeleton_csv.hpp"

#include "nao/tools/command.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace nao::tools {
namespace {

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::istringstream in(line);
  while (std::getline(in, cell, ',')) cells.push_back(cell);
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

}  // namespace

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
      out << ',' << frame.p_W[i].x() << ',' << frame.p_W[i].y() << ',' << frame.p_W[i].z() << ",1";
    else
      out << ",0,0,0,0";
  }
}

void writeSkeletonCsv(const std::string& path, const Skeleton& frames) {
  std::ofstream out(path);
  if (!out) throw UserError("cannot write " + path);
  out.precision(10);
  out << skeletonCsvHeader() << '\n';
  for (const SkeletonFrame& f : frames) {
    writeSkeletonColumns(out, f);
    out << '\n';
  }
  if (!out) throw UserError("error while writing " + path);
}

Skeleton readSkeletonCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw UserError("cannot open skeleton CSV " + path);
  std::string line;
  if (!std::getline(in, line)) throw UserError(path + ": empty file, expected a skeleton CSV header");
  const std::vector<std::string> header = splitCsvLine(line);
  std::unordered_map<std::string, std::size_t> column;
  for (std::size_t c = 0; c < header.size(); ++c) column[header[c]] = c;
  auto require = [&](const std::string& name) {
    const auto it = column.find(name);
    if (it == column.end()) throw UserError(path + ": missing column '" + name + "'");
    return it->second;
  };
  const std::size_t c_t = require("t_s");
  std::array<std::array<std::size_t, 4>, kNumSkeletonPoints> c_pt;
  for (int i = 0; i < kNumSkeletonPoints; ++i)
    for (int k = 0; k < 4; ++k)
      c_pt[i][k] = require(std::string(kSkeletonPointNames[i]) + std::array<const char*, 4>{"_x", "_y", "_z", "_ok"}[k]);

  Skeleton frames;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty()) continue;
    const std::vector<std::string> cells = splitCsvLine(line);
    if (cells.size() < header.size())
      throw UserError(path + ":" + std::to_string(line_no) + ": " + std::to_string(cells.size()) + " values, expected " +
                      std::to_string(header.size()));
    auto number = [&](std::size_t c) {
      char* end = nullptr;
      const double v = std::strtod(cells[c].c_str(), &end);
      if (cells[c].empty() || *end != '\0' || !std::isfinite(v))
        throw UserError(path + ":" + std::to_string(line_no) + ": column '" + header[c] + "' holds '" + cells[c] +
                        "', expected a finite number");
      return v;
    };
    SkeletonFrame f;
    f.t_s = number(c_t);
    if (!frames.empty() && f.t_s <= frames.back().t_s)
      throw UserError(path + ":" + std::to_string(line_no) + ": time t_s=" + cells[c_t] + " does not increase");
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      f.ok[i] = number(c_pt[i][3]) != 0.0;
      f.p_W[i] = f.ok[i] ? Eigen::Vector3d(number(c_pt[i][0]), number(c_pt[i][1]), number(c_pt[i][2]))
                         : Eigen::Vector3d::Zero();
    }
    frames.push_back(f);
  }
  return frames;
}

}  // namespace nao::tools
