// A nao_rt run's results, after the loop (docs/nao_rt.md): the metrics of the tick records, the
// run directory (ticks.csv, attention.bin, summary.json) and the printed summary.
// Runs after deactivate: allocates, writes files, throws std::runtime_error on output errors.
#pragma once

#include "rt_config.hpp"
#include "nao/metrics.hpp"

#include "nao/attention_ring.hpp"
#include "nao/controller.hpp"
#include "nao/lola_backend.hpp"
#include "nao/policy_kernels.hpp"

#include <array>
#include <cstdint>
#include <iosfwd>
#include <limits>
#include <string>
#include <vector>

namespace nao::rt {

/// Exit statuses of a run that the robot backend ended early (after its safe stop; the run
/// directory is still written).
inline constexpr int kExitRobotLinkLost = 3;  ///< LoLA socket closed or silent
inline constexpr int kExitStopSignal = 4;     ///< SIGINT/SIGTERM

/// What a run produced (also in summary.json).
struct RunReport {
  int status = 1;              ///< exit status: 0 done, 1 configure/load/output error, 2 usage error,
                               ///< kExitRobotLinkLost, kExitStopSignal
  std::string error;           ///< one line (without "nao_rt: ") when status != 0
  std::int64_t ticks = 0;
  std::int64_t overruns = 0;   ///< ticks that missed their deadline (--realtime only)
  std::array<std::int64_t, kNumControllerFaults> faults{};  ///< ticks with each fault bit
  std::int64_t allocations_after_activate = -1;            ///< control thread; -1: not counted
  double ee_rmse_m = std::numeric_limits<double>::quiet_NaN();  ///< against the reference's target
  LatencyStats tick_us, retarget_us, policy_us, sim_us;
  std::string summary_json;    ///< the text of summary.json (also without --log)
};

/// What the loop measured beyond the records.
struct LoopTotals {
  std::int64_t allocations = -1;     ///< the control thread's, activate to deactivate (-1: not counted)
  std::int64_t reader_allocations = -1;  ///< the live camera reader thread's, same window (-1: not counted)
  std::int64_t skipped_periods = 0;  ///< --realtime: whole periods skipped after overruns
  double wall_s = 0.0;
  std::string realtime_scheduling;   ///< "SCHED_FIFO + mlockall", or what was not permitted
  bool lola = false;                 ///< the robot was LoLA (summary.json "robot", "lola")
  std::string lola_socket;
  std::string lola_io_scheduling;    ///< the I/O thread's policy and priority; empty without one
  LolaCounters lola_counters;
  std::vector<std::int64_t> lola_latency_ns;  ///< per answered cycle
  RobotStop stop = RobotStop::kNone;          ///< the backend ended the run early
  /// The training demonstration whose run code the policy ran with (summary.json "run_code");
  /// empty: none (the zero code, or a model without run codes).
  std::string run_code;
  /// The ActionLaw that acted in place of the policy (summary.json "action_law"); empty: the policy.
  std::string action_law;
  /// The kernel the run's weights were bound with (PolicyWeights::kernel; summary.json
  /// model.kernel). The default is the binders' own default.
  PolicyKernel kernel = bestPolicyKernel();
};

/// ticks.csv's header line (no newline): the contract's columns in order.
std::string ticksCsvHeader();

/// One ticks.csv row (no newline): doubles in shortest round-trip form, `_us` columns 0 when
/// zero_timing.
std::string ticksCsvRow(const TickRecord& r, bool zero_timing);

/// After the loop: metrics, summary.json, ticks.csv, attention.bin (from `ring`), the printed
/// summary on `out`. Throws std::runtime_error on output errors.
void finishRun(const RunOptions& options, const PreparedRun& prepared, const std::vector<TickRecord>& records,
               const AttentionRingView& ring, const LoopTotals& totals, std::ostream& out, RunReport& report);

}  // namespace nao::rt
