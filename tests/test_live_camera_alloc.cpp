// The control thread's side of the live camera source allocates nothing: takeNewestFromRT under
// the counting allocator, while a replay feeds the source; the reader thread's allocations are
// counted on their own (ThreadAllocations) and never reach the control thread's count.
#include "support/alloc_counter.hpp"
#include "support/live_recording.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <chrono>
#include <thread>

using namespace nao;
using namespace nao::test;

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
