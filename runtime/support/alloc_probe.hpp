// An AllocationProbe (allocation_probe.hpp) backed by the counting allocator (alloc_counter.hpp):
// the count of the thread that calls start() until stop(). nao_rt's main (rt_main.hpp) and the
// allocation tests of a whole run count with it; only programs that link alloc_counter.cpp
// include this header.
#pragma once

#include "alloc_counter.hpp"
#include "allocation_probe.hpp"

#include <cstdint>
#include <optional>

namespace nao {

struct CountingProbe : AllocationProbe {
  std::optional<CountAllocations> counter;
  void start() override { counter.emplace(); }
  std::int64_t stop() override {
    const std::int64_t n = counter->count();
    counter.reset();
    return n;
  }
};

}  // namespace nao
