// nao_rt's main (docs/nao_rt.md) for compiled architectures: the command line (rt_cli), the
// model info (rt_info), and the run (rt_run) with the counting allocator's probes that
// summary.json's allocation counts come from. nao_rt_main.cpp instantiates it with the
// compiled-in model's dimensions and the paper and small ones beside them (a --weights file of
// either runs without a build of its own); tests/lola's slower-CPU nao_rt with a clock of its own.
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

/// The run of `options` with the policy compiled as Dims, its allocations counted in nao_rt.
template <class Dims>
int runCounted(RunOptions& options) {
#if NAO_RT_COUNT_ALLOCATIONS
  detail::ControlAndIoProbe probe;
  detail::ReaderCounter reader;  // outlives the run, whose reader thread it is attached to
  options.reader_allocations = &reader;
  return runMain<Dims>(options, std::cout, std::cerr, &probe);
#else
  return runMain<Dims>(options, std::cout, std::cerr, nullptr);
#endif
}

/// The architecture of a --weights file, if it reads as a model.bin (a file that does not is
/// the run's to report).
inline std::optional<PolicyArch> weightsArch(const std::string& path) {
  if (path.empty()) return std::nullopt;
  try {
    return readModelFile(path).header.arch;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// nao_rt: parses the command line, then --info or the run of the model. Dims are the compiled-in
/// model's (`compiled`: that model, or none); a --weights file whose step Dims do not compute runs
/// with the first of `Others` that does (each one more instantiation of the loop in the binary).
/// `clock` times the controller's stages (nullptr: CLOCK_MONOTONIC). Returns the exit status.
template <class Dims, class... Others>
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
      info.computes = [](const PolicyArch& a) { return (computesPolicyArch<Dims>(a) || ... || computesPolicyArch<Others>(a)); };
      return runInfo(info, std::cout, std::cerr);
    }

    if constexpr (sizeof...(Others) > 0) {
      const std::optional<PolicyArch> arch = weightsArch(cl.run.weights_path);
      if (arch && !computesPolicyArch<Dims>(*arch) && (computesPolicyArch<Others>(*arch) || ...))
        return withPolicyDims<Others...>(*arch, [&](auto dims) { return runCounted<decltype(dims)>(cl.run); });
    }
    return runCounted<Dims>(cl.run);
  } catch (const std::exception& e) {
    std::cerr << "nao_rt: " << oneLine(e.what()) << "\n";
    return 1;
  }
}

}  // namespace nao::rt
