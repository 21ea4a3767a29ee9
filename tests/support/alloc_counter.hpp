// Counts heap allocations made by the current thread while a CountAllocations is alive.
//
// Linking alloc_counter.cpp into a test executable replaces malloc, calloc, realloc,
// memalign-family functions and every operator new with versions that count and then
// forward to glibc. Not usable under AddressSanitizer, which owns malloc itself.
#pragma once

#include <cstdint>

namespace nao::test {

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  CountAllocations(const CountAllocations&) = delete;
  CountAllocations& operator=(const CountAllocations&) = delete;

  /// Allocations counted on this thread since construction.
  std::int64_t count() const;

 private:
  std::int64_t start_;
};

}  // namespace nao::test
