// nao_rt as a separate process per run (the evaluation scores nao_rt's whole loop): the jobs, a
// pool that runs them a few at a time, and their summary.json. Offline code.
#pragma once

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace nao::tools {

/// One nao_rt process.
struct Job {
  std::string what;               ///< for progress and errors, e.g. "elbow autonomous elbow_012"
  std::vector<std::string> argv;  ///< argv[0] = nao_rt
  std::filesystem::path dir;      ///< run directory (--log), holds nao_rt.log
};

/// Runs the jobs, at most `parallel` at a time, each with its output in DIR/nao_rt.log. On the
/// first failure no new job starts; the running ones finish, then a UserError names the run and
/// nao_rt's own last line.
void runJobs(const std::vector<Job>& jobs, int parallel);

/// The job's summary.json. Throws UserError when it is missing or not an object.
nlohmann::ordered_json readSummary(const Job& job);

}  // namespace nao::tools
