// Counts heap allocations made by the current thread while a CountAllocations is alive.
//
// Linking alloc_counter.cpp into an executable replaces malloc, calloc, realloc, the
// memalign family and every operator new with versions that count and then forward to glibc.
// Linked only into nao_rt (summary.json allocations_after_activate) and the test suites named
// test_*_alloc.cpp; never into a library. Not usable under AddressSanitizer, which owns malloc
// itself. The count is per thread: the control loop runs on one thread.
#pragma once

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

namespace test {
using nao::CountAllocations;  // the name the test suites use
}  // namespace test

}  // namespace nao
