// nao_toolchain: the offline pipeline, one subcommand per stage (see --help).
#include "nao/tools/command.hpp"

#include <algorithm>
#include <cstring>
#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{
      "nao_toolchain: offline pipeline of nao-rt. Human demonstrations (OpenPose BODY_25 from two or\n"
      "more cameras, or the synthesiser) -> triangulation -> embodiment-gap retargeting onto the NAO V6 arm."};
  app.require_subcommand(1);
  auto& registry = nao::tools::commandRegistry();
  std::sort(registry.begin(), registry.end(),
            [](const auto& a, const auto& b) { return std::strcmp(a.name, b.name) < 0; });
  for (const auto& entry : registry) entry.setup(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    const auto parsed = app.get_subcommands();
    std::cerr << "nao_toolchain" << (parsed.empty() ? "" : " " + parsed.front()->get_name()) << ": " << e.what()
              << "\n";
    return 1;
  }
  return 0;
}
