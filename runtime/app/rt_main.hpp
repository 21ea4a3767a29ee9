// nao_rt's main (docs/nao_rt.md) for a compiled architecture Dims: the command
// line (rt_cli), the model info (rt_info), and the run (rt_run) with the counting allocator's
// probes that summary.json's allocation counts come from. nao_rt_main.cpp instantiates it with
// the compiled-in model; tests/lola's slower-CPU nao_rt with a clock of its own.
#pragma once

#include "rt_cli.hpp"
#include "rt_info.hpp"
#include "rt_run.hpp"

#if NAO_RT_COUNT_ALLOCATIONS
#include "alloc_probe.hpp"
#endif

#include <iostream>
#include <optional>

namespace nao::rt {

#if NAO_RT_COUNT_ALLOCATIONS
namespace detail {

// The control thread's count from activate to deactivate (allocations_after_activate; the
// counter is per thread: start and stop run on the thread counted), and the LoLA I/O thread's
// as its companion (lola.io_allocations).
struct ControlAndIoProbe final : CountingProbe {
  CountingProbe io;
  AllocationProbe* companion() override { return &io; }
};

// The live camera reader thread's, readable from the control thread (camera.reader_allocations).
struct ReaderCounter final : ThreadAllocationCounter {
  ThreadAllocations sink;
  void attach() override { countThreadAllocationsInto(&sink); }
  std::int64_t count() const override { return sink.count.load(std::memory_order_relaxed); }
};

}  // namespace detail
#endif

/// nao_rt: parses the command line, then --info or the run of the model compiled as Dims
/// (`compiled`: the compiled-in model, or none). `clock` times the controller's stages
/// (nullptr: CLOCK_MONOTONIC). Returns the exit status.
template <class Dims>
int naoRtMain(int argc, const char* const* argv, const ModelImage& compiled, ControllerClock* clock = nullptr) {
  try {
    CommandLine cl;
    cl.run.compiled = compiled;
    cl.run.clock = clock;
    const int parsed = parseCommandLine(argc, argv, cl, std::cout, std::cerr);
    if (parsed >= 0) return parsed;

    if (cl.info) {
      InfoOptions info;
      info.weights_path = cl.run.weights_path;
      info.urdf_path = cl.run.urdf_path;
      info.compiled = cl.run.compiled;
      info.precision = cl.run.precision;
      info.kernel = runPolicyKernel(cl.run.policy_kernel);
      return runInfo(info, std::cout, std::cerr);
    }

#if NAO_RT_COUNT_ALLOCATIONS
    detail::ControlAndIoProbe probe;
    detail::ReaderCounter reader;  // outlives the run, whose reader thread it is attached to
    cl.run.reader_allocations = &reader;
    return runMain<Dims>(cl.run, std::cout, std::cerr, &probe);
#else
    return runMain<Dims>(cl.run, std::cout, std::cerr, nullptr);
#endif
  } catch (const std::exception& e) {
    std::cerr << "nao_rt: " << oneLine(e.what()) << "\n";
    return 1;
  }
}

}  // namespace nao::rt
