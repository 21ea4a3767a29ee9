// Reading CSV files (skeleton, retarget, features): columns by header name, numbers checked,
// errors (InputError) that name the file, the line and the column. Configure-time code.
#pragma once

#include <cstddef>
#include <fstream>
#include <string>
#include <unordered_map>
#include <vector>

namespace nao {

class CsvReader {
 public:
  /// Opens `path` and reads its header line. `what` names the kind of file in errors
  /// ("skeleton CSV"). Throws InputError when the file cannot be opened or is empty.
  CsvReader(const std::string& path, const std::string& what);

  /// Index of the column named `name`. Throws InputError naming the file and the column.
  std::size_t column(const std::string& name) const;

  /// Moves to the next non-empty data line; false at the end of the file.
  bool next();

  /// The current line's value in column `c` as a finite number. Throws InputError with
  /// file:line, the column's name and the text found for a short row, a non-number or NaN/inf.
  double number(std::size_t c) const;

  /// "path:line" of the current line, for the caller's own messages.
  std::string where() const;

  std::size_t columns() const { return header_.size(); }
  std::size_t cells() const { return cells_.size(); }

 private:
  std::string path_;
  std::ifstream in_;
  std::vector<std::string> header_;
  std::unordered_map<std::string, std::size_t> index_;
  std::vector<std::string> cells_;
  int line_ = 1;
};

}  // namespace nao
