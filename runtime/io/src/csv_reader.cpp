#include "nao/csv_reader.hpp"

#include "nao/input_error.hpp"

#include <cmath>
#include <cstdlib>
#include <sstream>

namespace nao {
namespace {

std::vector<std::string> splitLine(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::istringstream in(line);
  while (std::getline(in, cell, ',')) cells.push_back(cell);
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

}  // namespace

CsvReader::CsvReader(const std::string& path, const std::string& what) : path_(path), in_(path) {
  if (!in_) throw InputError("cannot open " + what + " " + path);
  std::string line;
  if (!std::getline(in_, line)) throw InputError(path + ": empty file, expected a " + what + " header");
  header_ = splitLine(line);
  for (std::size_t c = 0; c < header_.size(); ++c) index_[header_[c]] = c;
}

std::size_t CsvReader::column(const std::string& name) const {
  const auto it = index_.find(name);
  if (it == index_.end()) throw InputError(path_ + ": missing column '" + name + "'");
  return it->second;
}

bool CsvReader::next() {
  std::string line;
  while (std::getline(in_, line)) {
    ++line_;
    if (line.empty()) continue;
    cells_ = splitLine(line);
    return true;
  }
  return false;
}

double CsvReader::number(std::size_t c) const {
  if (c >= cells_.size())
    throw InputError(where() + ": " + std::to_string(cells_.size()) + " values, expected " +
                    std::to_string(header_.size()));
  char* end = nullptr;
  const double v = std::strtod(cells_[c].c_str(), &end);
  if (cells_[c].empty() || *end != '\0' || !std::isfinite(v))
    throw InputError(where() + ": column '" + header_[c] + "' holds '" + cells_[c] + "', expected a finite number");
  return v;
}

std::string CsvReader::where() const { return path_ + ":" + std::to_string(line_); }

}  // namespace nao
