// Live camera source latency (runtime/live/include/nao/live_camera.hpp): a synthesised two-camera
// recording (elbow circle, 150 frames = 5 s at 30 fps) replayed in process into fresh camera
// folders the way OpenPose writes (nao_toolchain replay's code: a plain file in three chunks),
// the live source reading them, and a control loop taking the newest skeleton.
//
// BM_LiveCameraLatency/P: the control loop takes every P µs (1000: the pipeline's own latency;
//   100000: what nao_rt's 10 Hz loop sees, the pipeline plus up to one tick of waiting). One
//   iteration = one whole replay (real time). Counters: latency_p50_ms, latency_p99_ms,
//   latency_max_ms from a frame's newest file appearing (the reader's inotify event) to the
//   first take of its skeleton (the LiveCamera's own record, one sample per skeleton taken);
//   reader_p50_ms, reader_p99_ms from the same appearance to the skeleton's publication (read,
//   parse, pair, triangulate, filters); taken = skeletons taken.
// BM_TakeNewest: one takeNewestFromRT of a fresh skeleton (the control thread's cost per tick).
//
// Run on an idle machine; each replay takes 5 s:
//   build/bin/nao_bench --benchmark_filter='BM_LiveCamera|BM_TakeNewest' --benchmark_repetitions=3
#include "nao/live_camera.hpp"
#include "nao/tools/calibration.hpp"
#include "nao/tools/replay.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/triangulate.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using namespace nao;

constexpr int kFrames = 150;

// The recording, written once: DIR/elbow_000/ with cam0/, cam1/ cut to kFrames frames.
const fs::path& recording() {
  static const fs::path dir = [] {
    const fs::path root = fs::temp_directory_path() / "nao_bench_live_camera";
    fs::remove_all(root);
    const tools::SynthDemo demo = tools::generateDemo(tools::Movement::kElbow, 0, 11, false);
    tools::writeDemo(demo, root.string());
    const fs::path d = root / demo.name;
    for (const std::string& cam : tools::demoCameraDirs(d.string()))
      for (const fs::directory_entry& e : fs::directory_iterator(cam)) {
        const auto k = openPoseFrameIndex(e.path().filename().string());
        if (k && *k >= kFrames) fs::remove(e.path());
      }
    return d;
  }();
  return dir;
}

timespec monotonicNow() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts;
}

double quantileMs(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

void BM_LiveCameraLatency(benchmark::State& state) {
  const auto period = std::chrono::microseconds(state.range(0));
  LatencyStats stats;
  std::vector<double> reader_ms;
  std::uint64_t taken = 0;
  int run = 0;
  for (auto _ : state) {
    const fs::path rig = fs::temp_directory_path() / "nao_bench_live_camera" / ("rig" + std::to_string(run++));
    fs::remove_all(rig);
    const std::vector<std::string> targets = {(rig / "cam0").string(), (rig / "cam1").string()};
    LiveCameraConfig cfg;
    cfg.dirs = targets;
    cfg.cameras = tools::readCalibration((recording() / "calibration.json").string());
    std::mutex mutex;
    std::vector<double> reader;
    std::atomic<long long> newest{-1};
    cfg.on_skeleton = [&](const LiveSkeleton& r) {
      std::lock_guard<std::mutex> lock(mutex);
      reader.push_back(static_cast<double>(r.published_ns - r.arrival_ns) * 1e-6);
      newest.store(r.frame_index);
    };
    LiveCamera live(cfg);
    tools::ReplayOptions replay;
    replay.recording = recording().string();
    replay.targets = targets;
    std::thread writer([&replay] { tools::replayRecording(replay); });
    SkeletonFrame out;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    auto next = std::chrono::steady_clock::now();
    while (newest.load() < kFrames - 1 && std::chrono::steady_clock::now() < deadline) {
      takeNewestFromRT(live, monotonicNow(), out);
      next += period;
      std::this_thread::sleep_until(next);
    }
    takeNewestFromRT(live, monotonicNow(), out);
    writer.join();
    stats = live.latencyStats();
    taken = live.counters().takes_fresh;
    std::lock_guard<std::mutex> lock(mutex);
    reader_ms = reader;
  }
  state.counters["latency_p50_ms"] = stats.p50_ms;
  state.counters["latency_p99_ms"] = stats.p99_ms;
  state.counters["latency_max_ms"] = stats.max_ms;
  state.counters["reader_p50_ms"] = quantileMs(reader_ms, 0.5);
  state.counters["reader_p99_ms"] = quantileMs(reader_ms, 0.99);
  state.counters["taken"] = static_cast<double>(taken);
}
BENCHMARK(BM_LiveCameraLatency)->Arg(1000)->Arg(100000)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_TakeNewest(benchmark::State& state) {
  const fs::path rig = fs::temp_directory_path() / "nao_bench_live_camera" / "take";
  fs::remove_all(rig);
  const std::vector<std::string> targets = {(rig / "cam0").string(), (rig / "cam1").string()};
  LiveCameraConfig cfg;
  cfg.dirs = targets;
  cfg.cameras = tools::readCalibration((recording() / "calibration.json").string());
  std::atomic<long long> newest{-1};
  cfg.on_skeleton = [&newest](const LiveSkeleton& r) { newest.store(r.frame_index); };
  LiveCamera live(cfg);
  tools::ReplayOptions replay;
  replay.recording = recording().string();
  replay.targets = targets;
  replay.speed = 10.0;
  tools::replayRecording(replay);
  while (newest.load() < kFrames - 1) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  SkeletonFrame out;
  LiveSkeleton record;
  if (!takeNewestFromRT(live, monotonicNow(), out, &record)) {
    state.SkipWithError("no skeleton to take");
    return;
  }
  // A fixed "now" at the skeleton's arrival keeps it fresh for the whole benchmark.
  const timespec now{static_cast<time_t>(record.arrival_ns / 1000000000), static_cast<long>(record.arrival_ns % 1000000000)};
  for (auto _ : state) {
    benchmark::DoNotOptimize(takeNewestFromRT(live, now, out));
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_TakeNewest);

}  // namespace
