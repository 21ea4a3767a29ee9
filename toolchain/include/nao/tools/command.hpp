// Subcommands of nao_toolchain register themselves, so each lives in its own file:
//
//   namespace { void setup(CLI::App& app) { ... } }
//   NAO_REGISTER_COMMAND(synth, setup)
//
// setup() adds the subcommand to `app` with its options and a callback that does the work.
// Errors in the work: throw nao::tools::UserError (or any std::exception) with one line a
// user can act on; main prints it after "nao_toolchain <command>: " and exits 1.
#pragma once

#include "nao/input_error.hpp"

#include <CLI/CLI.hpp>

#include <stdexcept>
#include <string>
#include <vector>

namespace nao::tools {

/// A problem with the user's input or work: the runtime's InputError, so an error from a parser the
/// toolchain shares with the runtime (skeleton CSV, ...) is the same kind as its own.
using UserError = nao::InputError;

using CommandSetup = void (*)(CLI::App& app);

struct CommandEntry {
  const char* name;
  CommandSetup setup;
};

/// All registered commands, in registration order (sorted by name in main).
std::vector<CommandEntry>& commandRegistry();

struct RegisterCommand {
  RegisterCommand(const char* name, CommandSetup setup) { commandRegistry().push_back({name, setup}); }
};

}  // namespace nao::tools

#define NAO_REGISTER_COMMAND(name, setup_fn) \
  static const ::nao::tools::RegisterCommand nao_register_command_##name{#name, setup_fn};
