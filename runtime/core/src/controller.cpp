// Non-template parts of the controller (nao/controller.hpp).
#include "nao/controller.hpp"

#include <ctime>

namespace nao {

std::int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

std::int64_t SteadyClock::nowNs() { return monotonicNs(); }

}  // namespace nao
