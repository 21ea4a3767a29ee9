// The control thread's side of the live camera source allocates nothing: takeNewestFromRT under
// the counting allocator, while a replay feeds the source; the reader thread's allocations are
// counted on their own (ThreadAllocations) and never reach the control thread's count. And a
// camera folder that comes back costs the reader thread the same allocations whether it holds
// two thousand frame files or twenty thousand (an hour of OpenPose output is ~106,000).
#include "support/alloc_counter.hpp"
#include "support/live_recording.hpp"

#include <doctest/doctest.h>

#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <thread>

using namespace nao;
using namespace nao::test;

namespace {

namespace fs = std::filesystem;

std::string frameFileName(long long index) {
  char name[64];
  std::snprintf(name, sizeof name, "cam_%012lld_keypoints.json", index);
  return name;
}

// Waits (bounded) until `done` holds; whether it does.
template <typename Pred>
bool waitUntil(Pred done, double timeout_s = 5.0) {
  for (double t = 0.0; t < timeout_s; t += 0.005) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return done();
}

// Waits until the reader thread has made no allocation for 100 ms (it is idle: no file to parse,
// no frame to process); its count then.
std::int64_t settledCount(const ThreadAllocations& a) {
  std::int64_t last = a.count.load();
  for (int quiet = 0, k = 0; quiet < 20 && k < 2000; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    const std::int64_t now = a.count.load();
    quiet = now == last ? quiet + 1 : 0;
    last = now;
  }
  return last;
}

// Bytes the heap holds from the system (every arena, and mmapped blocks): what stays resident
// under nao_rt's mlockall once touched.
long long heapFromSystem() {
  const struct mallinfo2 m = mallinfo2();
  return static_cast<long long>(m.arena + m.hblkhd);
}

struct ReturnCost {
  std::int64_t allocations[2] = {0, 0};  // reader thread, during the first and the second return
  long long heap_growth[2] = {0, 0};     // heapFromSystem() across each return, bytes
  long long newest = -1;                 // newest frame processed at the end
  std::uint32_t newest_cameras = 0;      // its cameras
};

// Camera folder 0 holds `n_files` old frame files (an earlier hour's, ignored at start); both
// cameras then write frames, folder 0 is moved away and back twice (the reader thread counted
// across each return), and both cameras write again.
ReturnCost folderReturnCost(const std::string& name, int n_files) {
  const fs::path base = freshTestDir(name);
  const fs::path rec = shortRecording(name + "_rec", tools::Movement::kElbow, 0, 20);
  const std::vector<std::string> targets = {(base / "rig" / "cam0").string(), (base / "rig" / "cam1").string()};
  for (const std::string& t : targets) fs::create_directories(t);
  for (int k = 0; k < n_files; ++k) std::ofstream(fs::path(targets[0]) / frameFileName(k));
  // The recording's frames, in index order per camera, written as indices n_files + k.
  std::vector<std::vector<fs::path>> frames;
  for (const std::string& cam : tools::demoCameraDirs(rec.string())) {
    frames.emplace_back();
    for (const fs::directory_entry& e : fs::directory_iterator(cam)) frames.back().push_back(e.path());
    std::sort(frames.back().begin(), frames.back().end());
  }
  REQUIRE(frames.size() == 2);
  const auto write = [&](int from, int to) {
    for (int k = from; k < to; ++k)
      for (std::size_t c = 0; c < 2; ++c)
        fs::copy_file(frames[c][static_cast<std::size_t>(k)], fs::path(targets[c]) / frameFileName(n_files + k));
  };

  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  ThreadAllocations reader;
  cfg.on_reader_start = [&reader] { countThreadAllocationsInto(&reader); };
  std::atomic<long long> newest{-1};
  std::atomic<std::uint32_t> newest_cameras{0};
  cfg.on_skeleton = [&](const LiveSkeleton& r) {
    newest_cameras.store(r.n_cameras);
    newest.store(r.frame_index);
  };
  ReturnCost cost;
  LiveCamera live(cfg);
  write(0, 10);
  REQUIRE(waitUntil([&] { return newest.load() == n_files + 9; }));
  const fs::path away = base / "away";
  for (int round = 0; round < 2; ++round) {
    fs::rename(targets[0], away);
    REQUIRE(waitUntil([&] { return live.counters().folder_gone == static_cast<std::uint64_t>(round + 1); }));
    const std::int64_t before = settledCount(reader);
    const long long heap_before = heapFromSystem();
    fs::rename(away, targets[0]);
    REQUIRE(waitUntil([&] { return live.counters().folder_back == static_cast<std::uint64_t>(round + 1); }));
    cost.allocations[round] = settledCount(reader) - before;
    cost.heap_growth[round] = heapFromSystem() - heap_before;
  }
  write(10, 20);
  waitUntil([&] { return newest.load() == n_files + 19; });
  cost.newest = newest.load() - n_files;
  cost.newest_cameras = newest_cameras.load();
  CHECK(live.counters().reader_errors == 0);
  CHECK(live.counters().capture_restarts == 0);
  return cost;
}

}  // namespace

TEST_CASE("taking the newest live skeleton allocates nothing on the control thread; the reader's allocations are its own") {
  const auto base = freshTestDir("alloc");
  const auto rec = shortRecording("alloc_rec", tools::Movement::kElbow, 3, 60);
  const std::vector<std::string> targets = {(base / "rig" / "cam0").string(), (base / "rig" / "cam1").string()};
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  ThreadAllocations reader_allocations;
  cfg.on_reader_start = [&reader_allocations] { countThreadAllocationsInto(&reader_allocations); };
  std::atomic<long long> newest{-1};
  cfg.on_skeleton = [&newest](const LiveSkeleton& r) { newest.store(r.frame_index); };
  LiveCamera live(cfg);
  ReplayThread replay(rec, targets, 2.0);
  SkeletonFrame out;
  LiveSkeleton record;
  int n_human = 0, n_takes = 0;
  std::int64_t control_allocations = 0;
  {
    CountAllocations count;
    // The control loop: take, as fast as the replay goes, until its last frame is in.
    while (newest.load() < 59 && n_takes < 200000) {
      n_human += takeNewestFromRT(live, monotonicNow(), out, &record) ? 1 : 0;
      ++n_takes;
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    control_allocations = count.count();
  }
  replay.join();
  MESSAGE(n_takes << " takes, " << n_human << " with a human; reader thread allocations "
                  << reader_allocations.count.load() << ", latency samples " << live.latencyStats().n);
  CHECK(newest.load() == 59);
  CHECK(n_human > 100);
  CHECK(control_allocations == 0);
  // The reader thread parses and triangulates: it allocates, and that is counted apart.
  CHECK(reader_allocations.count.load() > 1000);
}

TEST_CASE("a camera folder that comes back costs the reader thread the same whatever number of files it holds") {
  const ReturnCost small = folderReturnCost("return_small", 2000);
  const ReturnCost big = folderReturnCost("return_big", 20000);
  MESSAGE("reader allocations while the folder came back (first, second return): 2,000 files "
          << small.allocations[0] << ", " << small.allocations[1] << "; 20,000 files " << big.allocations[0] << ", "
          << big.allocations[1] << "; heap taken from the system across the second return: " << small.heap_growth[1]
          << " B, " << big.heap_growth[1] << " B");
  // The folder's old files are looked at one by one and none is kept: the cost of a return does
  // not depend on how many there are (a list of their names would be > 18,000 allocations more).
  CHECK(std::abs(big.allocations[1] - small.allocations[1]) <= 16);
  CHECK(std::abs(big.allocations[0] - small.allocations[0]) <= 16);
  CHECK(big.allocations[1] < 1000);
  // And the source goes on: both cameras' new frames are processed together after the returns.
  CHECK(small.newest == 19);
  CHECK(big.newest == 19);
  CHECK(small.newest_cameras == 2);
  CHECK(big.newest_cameras == 2);
}
