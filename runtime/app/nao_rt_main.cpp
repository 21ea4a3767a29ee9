// nao_rt: the NAO V6 right-arm imitation controller runtime (DESIGN section 9, docs/nao_rt.md).
//
// The policy is compiled in (models/default.bin through nao_codegen at build time); --weights
// loads another model.bin of the same architecture. This file only wires the command line
// (rt_cli), the model info (rt_info) and the run (rt_run) to the compiled dimensions and to the
// counting allocator that summary.json's allocations_after_activate comes from.
#include "rt_cli.hpp"
#include "rt_info.hpp"
#include "rt_run.hpp"

#if NAO_RT_COUNT_ALLOCATIONS
#include "alloc_counter.hpp"
#endif
#if NAO_HAVE_COMPILED_MODEL
#include "nao/compiled_model.hpp"
#include "nao_model_dims.hpp"
#endif

#include <iostream>
#include <optional>

namespace {

#if NAO_HAVE_COMPILED_MODEL
using RtDims = nao::compiled::Dims;
#else
// Without a compiled-in model, --weights must be of the paper architecture.
using RtDims = nao::PaperPolicyDims;
#endif

#if NAO_RT_COUNT_ALLOCATIONS
// Counts one thread's allocations from activate to deactivate (the counter is per thread:
// start and stop run on the thread counted): the control thread's, allocations_after_activate.
struct ThreadProbe : nao::rt::AllocationProbe {
  std::optional<nao::CountAllocations> counter;
  void start() override { counter.emplace(); }
  std::int64_t stop() override {
    const std::int64_t n = counter->count();
    counter.reset();
    return n;
  }
};

// The control thread's, and the LoLA I/O thread's as its companion (lola.io_allocations).
struct CountingProbe final : ThreadProbe {
  ThreadProbe io;
  nao::rt::AllocationProbe* companion() override { return &io; }
};

// The live camera reader thread's, readable from the control thread (camera.reader_allocations).
struct ReaderCounter final : nao::rt::ThreadAllocationCounter {
  nao::ThreadAllocations sink;
  void attach() override { nao::countThreadAllocationsInto(&sink); }
  std::int64_t count() const override { return sink.count.load(std::memory_order_relaxed); }
};
#endif

}  // namespace

int main(int argc, char** argv) {
  try {
    nao::rt::CommandLine cl;
#if NAO_HAVE_COMPILED_MODEL
    cl.run.compiled = nao::compiled::modelImage();
#endif
    const int parsed = nao::rt::parseCommandLine(argc, argv, cl, std::cout, std::cerr);
    if (parsed >= 0) return parsed;

    if (cl.info) {
      nao::rt::InfoOptions info;
      info.weights_path = cl.run.weights_path;
      info.urdf_path = cl.run.urdf_path;
      info.compiled = cl.run.compiled;
      info.precision = cl.run.precision;
      return nao::rt::runInfo(info, std::cout, std::cerr);
    }

#if NAO_RT_COUNT_ALLOCATIONS
    CountingProbe probe;
    ReaderCounter reader;  // outlives the run, whose reader thread it is attached to
    cl.run.reader_allocations = &reader;
    return nao::rt::runMain<RtDims>(cl.run, std::cout, std::cerr, &probe);
#else
    return nao::rt::runMain<RtDims>(cl.run, std::cout, std::cerr, nullptr);
#endif
  } catch (const std::exception& e) {
    std::cerr << "nao_rt: " << nao::rt::oneLine(e.what()) << "\n";
    return 1;
  }
}
