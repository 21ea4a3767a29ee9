// The allocation probe: what counts the heap allocations of a run's threads from activate to
// deactivate, as the run and the LoLA backend's I/O thread call it. No dependency: a library
// takes a probe without linking the counting allocator, which backs it only in nao_rt and the
// allocation tests (CountingProbe, alloc_probe.hpp).
#pragma once

#include <cstdint>

namespace nao {

/// Counts the heap allocations of the thread that calls start() until stop() (nao_rt backs it
/// with its counting allocator; the allocation tests with theirs). A backend with a thread of
/// its own is given one for that thread.
struct AllocationProbe {
  virtual ~AllocationProbe() = default;
  virtual void start() = 0;
  virtual std::int64_t stop() = 0;
  /// A probe for one more thread (a backend's own), or nullptr if allocations are counted on
  /// the calling thread only.
  virtual AllocationProbe* companion() { return nullptr; }
};

}  // namespace nao
