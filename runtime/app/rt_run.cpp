// The real-time helpers of nao_rt's loop (rt_run.hpp): pacing on absolute deadlines and
// SCHED_FIFO + mlockall.
#include "rt_run.hpp"

#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <cerrno>
#include <cstring>

namespace nao::rt {

void sleepUntilNs(std::int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / 1000000000);
  ts.tv_nsec = static_cast<long>(t_ns % 1000000000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

RealtimeScheduling enterRealtime() {
  RealtimeScheduling s;
  s.old_policy = sched_getscheduler(0);
  sched_param old{};
  sched_getparam(0, &old);
  s.old_priority = old.sched_priority;
  std::string problems;
  sched_param fifo{};
  fifo.sched_priority = std::min(50, sched_get_priority_max(SCHED_FIFO));
  if (sched_setscheduler(0, SCHED_FIFO, &fifo) == 0)
    s.fifo = true;
  else
    problems = std::string("SCHED_FIFO: ") + std::strerror(errno);
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0)
    s.locked = true;
  else
    problems += (problems.empty() ? "" : "; ") + std::string("mlockall: ") + std::strerror(errno);
  if (!problems.empty())
    s.warning = "real-time scheduling not permitted (" + problems + ")";
  return s;
}

void leaveRealtime(RealtimeScheduling& s) {
  if (s.locked) munlockall();
  if (s.fifo) {
    sched_param old{};
    old.sched_priority = s.old_priority;
    sched_setscheduler(0, s.old_policy, &old);
  }
  s.locked = false;
  s.fifo = false;
}

}  // namespace nao::rt
