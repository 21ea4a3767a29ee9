// nao_toolchain replay: a recording's OpenPose frames played into camera folders at the capture
// rate (nao/tools/replay.hpp). Faults for tests come from NAO_REPLAY_FAULTS, not from flags.
#include "nao/tools/command.hpp"
#include "nao/tools/replay.hpp"
#include "nao/tools/triangulate.hpp"

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace nao::tools {
namespace {

struct ReplayArgs {
  std::string recording;
  std::string to;
  double fps = 30.0;
  double speed = 1.0;
};

std::vector<std::string> splitList(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream s(list);
  std::string item;
  while (std::getline(s, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

void run(const ReplayArgs& args) {
  ReplayOptions options;
  options.recording = args.recording;
  options.targets = splitList(args.to);
  options.fps = args.fps;
  options.speed = args.speed;
  options.faults = parseReplayFaults(std::getenv("NAO_REPLAY_FAULTS"), static_cast<int>(demoCameraDirs(args.recording).size()));
  const ReplayReport r = replayRecording(options);
  std::printf("replayed %d frame indices (%d files: %d truncated, %d without a person; %d not written) into %zu "
              "folders at %g frames/s\n",
              r.n_indices, r.n_files, r.n_truncated, r.n_no_person, r.n_lost, options.targets.size(),
              args.fps * args.speed);
}

void setup(CLI::App& app) {
  auto args = std::make_shared<ReplayArgs>();
  CLI::App* cmd = app.add_subcommand(
      "replay",
      "Play a recording's OpenPose frames (its cam0/, cam1/, ... folders, as synth writes them) into camera\n"
      "folders at the capture rate, written as OpenPose --write_json writes them (plain writes in a few chunks,\n"
      "not renamed into place): a stand-in for a live camera rig feeding the live camera source.\n"
      "The folders are made when their first frame is written. Exits 0 after the last frame. See docs/cameras.md.");
  cmd->add_option("--recording", args->recording, "recording folder with cam0/, cam1/, ... OpenPose folders")->required();
  cmd->add_option("--to", args->to, "comma-separated camera folders to write into, one per cam<k>/ in order")->required();
  cmd->add_option("--fps", args->fps, "capture rate of the recording, Hz")->check(CLI::Range(0.1, 1000.0))->capture_default_str();
  cmd->add_option("--speed", args->speed, "replay speed (2: twice as fast)")->check(CLI::Range(0.01, 100.0))->capture_default_str();
  cmd->callback([args] { run(*args); });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(replay, nao::tools::setup)
