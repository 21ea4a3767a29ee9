// nao_rt on a slower CPU, for the LoLA timing test (lola_hil.py slow:io_thread): every tick's work
// starts MS milliseconds late, busy-waited on the control thread as a slower processor (the NAO's
// Atom) would take them, not counted in tick_us.
//   usage: nao_rt_slow_cpu MS NAO_RT_ARGS...
// The compiled-in model and the counting allocator as in nao_rt; the extra time comes from the
// controller's clock, which nao_rt's run takes from its caller (RunOptions::clock).
#include "rt_main.hpp"

#include "nao/compiled_model.hpp"
#include "nao_model_dims.hpp"

#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {

// CLOCK_MONOTONIC, with a busy wait before the first of the controller's five readings a tick
// on a robot (t0, before the reference stage; four in updateController, one in finishTick).
struct SlowCpuClock final : nao::ControllerClock {
  std::int64_t extra_ns = 0;
  std::int64_t readings = 0;
  std::int64_t nowNs() override {
    if (readings++ % 5 == 0) {
      const std::int64_t until = nao::monotonicNs() + extra_ns;
      while (nao::monotonicNs() < until) {
      }
    }
    return nao::monotonicNs();
  }
};

}  // namespace

int main(int argc, char** argv) {
  const double ms = argc > 1 ? std::atof(argv[1]) : -1.0;
  if (!(ms >= 0.0 && ms <= 1000.0)) {
    std::fprintf(stderr, "usage: nao_rt_slow_cpu MS NAO_RT_ARGS... (MS: 0-1000)\n");
    return 2;
  }
  SlowCpuClock clock;
  clock.extra_ns = static_cast<std::int64_t>(ms * 1e6 + 0.5);
  // nao_rt's argv without MS.
  std::vector<const char*> args{argv[0]};
  for (int i = 2; i < argc; ++i) args.push_back(argv[i]);
  return nao::rt::naoRtMain<nao::compiled::Dims>(static_cast<int>(args.size()), args.data(), nao::compiled::modelImage(),
                                                  &clock);
}
