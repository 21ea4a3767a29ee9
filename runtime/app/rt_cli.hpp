// nao_rt's command line (CLI11), parsed into RunOptions (rt_config.hpp). A library function so
// the tests check the flags and their errors in process. Configure-time code.
#pragma once

#include "rt_config.hpp"

#include <iosfwd>

namespace nao::rt {

struct CommandLine {
  RunOptions run;
  bool info = false;  ///< --info: describe the model (rt_info.hpp) and exit
};

/// Parses argv. Returns -1 when the program should go on with `cl`; otherwise the exit status
/// to return at once: 0 after --help (printed on `out`), 2 after a bad flag or value (one line
/// "nao_rt: <problem> (nao_rt --help lists the flags)" on `err`).
int parseCommandLine(int argc, const char* const* argv, CommandLine& cl, std::ostream& out, std::ostream& err);

}  // namespace nao::rt
