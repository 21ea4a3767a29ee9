#include "nao/tools/command.hpp"

namespace nao::tools {

// In the library, not in main: test executables link the commands without nao_toolchain's main.
std::vector<CommandEntry>& commandRegistry() {
  static std::vector<CommandEntry> registry;
  return registry;
}

}  // namespace nao::tools
