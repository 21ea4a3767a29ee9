// Helpers of the live camera tests: a short synthetic recording on disk, its replay on a thread
// into camera folders, and a live camera source watching those folders.
#pragma once

#include "nao/live_camera.hpp"
#include "nao/tools/calibration.hpp"
#include "nao/tools/replay.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/triangulate.hpp"

#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace nao::test {

/// A fresh, empty folder under the system temp directory.
inline std::filesystem::path freshTestDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests" / "live_camera" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// Synthesised demonstration `index` of `movement` (seed 7), its frames cut to the first
/// `n_frames`: DIR/<demo>/ with cam0/, cam1/ and calibration.json. Returns the demo folder.
inline std::filesystem::path shortRecording(const std::string& name, tools::Movement movement, int index, int n_frames) {
  namespace fs = std::filesystem;
  const fs::path dir = freshTestDir(name);
  const tools::SynthDemo demo = tools::generateDemo(movement, index, 7, false);
  tools::writeDemo(demo, dir.string());
  const fs::path demo_dir = dir / demo.name;
  for (const std::string& cam : tools::demoCameraDirs(demo_dir.string()))
    for (const fs::directory_entry& e : fs::directory_iterator(cam)) {
      const auto k = openPoseFrameIndex(e.path().filename().string());
      if (k && *k >= n_frames) fs::remove(e.path());
    }
  return demo_dir;
}

/// Live camera configuration for `recording`'s calibration watching `targets`.
inline LiveCameraConfig liveConfigFor(const std::filesystem::path& recording, const std::vector<std::string>& targets) {
  LiveCameraConfig cfg;
  cfg.dirs = targets;
  cfg.cameras = tools::readCalibration((recording / "calibration.json").string());
  cfg.fps = 30.0;
  return cfg;
}

/// The replay of `recording` into `targets` on its own thread; join() waits for its end.
struct ReplayThread {
  tools::ReplayReport report;
  std::thread thread;
  ReplayThread(const std::filesystem::path& recording, const std::vector<std::string>& targets, double speed,
               const tools::ReplayFaults& faults = {}) {
    tools::ReplayOptions opt;
    opt.recording = recording.string();
    opt.targets = targets;
    opt.speed = speed;
    opt.faults = faults;
    thread = std::thread([this, opt] { report = tools::replayRecording(opt); });
  }
  void join() {
    if (thread.joinable()) thread.join();
  }
  ~ReplayThread() { join(); }
};

/// CLOCK_MONOTONIC now.
inline timespec monotonicNow() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts;
}

}  // namespace nao::test
