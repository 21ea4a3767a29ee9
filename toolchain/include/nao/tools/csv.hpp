// The CSV reader of the toolchain's files is the runtime's (nao/csv_reader.hpp).
#pragma once

#include "nao/csv_reader.hpp"

namespace nao::tools {
using nao::CsvReader;
}  // namespace nao::tools
