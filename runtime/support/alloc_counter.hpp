// Counts heap allocations made by the current thread while a CountAllocations is alive.
//
// Linking alloc_counter.cpp into an executable replaces malloc, calloc, realloc, the
// memalign family and every operator new with versions that count and then forward to glibc.
// Linked only into nao_rt (summary.json allocations_after_activate) and the test suites named
// test_*_alloc.cpp; never into a library. Not usable under AddressSanitizer, which owns malloc
// itself. The count is per thread: the control loop runs on one thread.
//
// Helper threads (the live camera's reader) count their own allocations apart from the control
// thread's: the thread attaches a ThreadAllocations (countThreadAllocationsInto, from inside the
// thread, e.g. through LiveCameraConfig::on_reader_start), and every allocation it makes from
// then on adds one to that record, which any thread may read. A thread's allocations never add
// to another thread's CountAllocations.
#pragma once

#include <atomic>
#include <cstdint>

namespace nao {

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  CountAllocations(const CountAllocations&) = delete;
  CountAllocations& operator=(const CountAllocations&) = delete;

  /// Allocations counted on this thread since construction. Real-time safe.
  std::int64_t count() const;

 private:
  std::int64_t start_;
};

/// An allocation count of one helper thread, readable from any thread.
struct ThreadAllocations {
  std::atomic<std::int64_t> count{0};  ///< allocations the attached thread made since attaching
};

/// From now on, every allocation of the calling thread adds one to `sink` (nullptr: stop). The
/// sink must outlive the attachment. Real-time safe (one thread-local store).
void countThreadAllocationsInto(ThreadAllocations* sink);

namespace test {
using nao::CountAllocations;  // the name the test suites use
}  // namespace test

}  // namespace nao
