#include "jobs.hpp"

#include "nao/tools/command.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

extern char** environ;

namespace nao::tools {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

std::string readText(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

std::string lastLine(const std::string& text) {
  std::istringstream in(text);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last;
}

pid_t spawn(const Job& job) {
  std::error_code ec;
  fs::create_directories(job.dir, ec);
  if (ec) throw UserError("cannot create " + job.dir.string() + ": " + ec.message());
  const std::string log = (job.dir / "nao_rt.log").string();
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<char*> argv;
  for (const std::string& a : job.argv) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw UserError("cannot start " + job.argv[0] + ": " + std::strerror(rc));
  return pid;
}

// Runs the jobs, at most `parallel` at a time. On the first failure no new job starts; the
// running ones finish, then the failure is reported (nao_rt's own last line).
}  // namespace

void runJobs(const std::vector<Job>& jobs, int parallel) {
  std::map<pid_t, std::size_t> running;
  std::size_t next = 0, done = 0;
  std::string failure;
  while (done < jobs.size()) {
    while (failure.empty() && next < jobs.size() && static_cast<int>(running.size()) < parallel) {
      running[spawn(jobs[next])] = next;
      ++next;
    }
    if (running.empty()) break;
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) throw UserError(std::string("waiting for nao_rt: ") + std::strerror(errno));
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const Job& job = jobs[it->second];
    running.erase(it);
    ++done;
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    std::fprintf(stderr, "evaluate: [%zu/%zu] %s%s\n", done, jobs.size(), job.what.c_str(), ok ? "" : " FAILED");
    if (!ok && failure.empty()) {
      const std::string line = lastLine(readText(job.dir / "nao_rt.log"));
      failure = job.what + ": nao_rt " +
                (WIFEXITED(status) ? "exit " + std::to_string(WEXITSTATUS(status)) : std::string("killed")) + ": " +
                (line.empty() ? "(no output)" : line) + " (log: " + (job.dir / "nao_rt.log").string() + ")";
    }
  }
  if (!failure.empty()) throw UserError(failure);
}

json readSummary(const Job& job) {
  const fs::path p = job.dir / "summary.json";
  const json j = json::parse(readText(p), nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw UserError(p.string() + ": not a JSON object (nao_rt did not finish?)");
  return j;
}

}  // namespace nao::tools
