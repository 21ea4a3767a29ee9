// The run directory and the printed summary of a nao_rt run (rt_rundir.hpp).
#include "rt_rundir.hpp"

#include "rt_live.hpp"

#include "nao/policy_kernels.hpp"
#include "nao/attention_shm.hpp"

#include <nlohmann/json.hpp>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <ostream>
#include <sstream>
#include <utility>

namespace nao::rt {
namespace {

namespace fs = std::filesystem;

std::string hex64(std::uint64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

void appendNumber(std::string& s, double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

void appendNumber(std::string& s, float v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

template <class Int>
void appendInt(std::string& s, Int v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

nlohmann::ordered_json statsJson(const LatencyStats& s) {
  return {{"p50", s.p50}, {"p99", s.p99}, {"max", s.max}};
}

// NaN has no JSON spelling: null.
nlohmann::ordered_json numberOrNull(double v) {
  return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

void writeText(const fs::path& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error("cannot write " + path.string());
  f.write(text.data(), static_cast<std::streamsize>(text.size()));
  f.close();
  if (!f) throw std::runtime_error("error while writing " + path.string());
}

std::string millis(double us) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f ms", us * 1e-3);
  return buf;
}

}  // namespace

std::string ticksCsvHeader() {
  std::string s = "tick,t_s";
  for (const char* name : {"q_ref", "r", "a", "q_cmd", "q"})
    for (int j = 0; j < kNumJoints; ++j) s += std::string(",") + name + "_" + std::to_string(j);
  s += ",ee_x,ee_y,ee_z,ee_ref_x,ee_ref_y,ee_ref_z";
  for (int j = 0; j < kNumJoints; ++j) s += ",att_" + std::to_string(j);
  s += ",fault,tick_us,retarget_us,policy_us,sim_us";
  // Appended (the columns before keep their positions): the raw attention mass.
  for (int j = 0; j < kNumJoints; ++j) s += ",attm_" + std::to_string(j);
  return s;
}

std::string ticksCsvRow(const TickRecord& r, bool zero_timing) {
  std::string s;
  s.reserve(1024);
  appendInt(s, r.tick);
  s += ',';
  appendNumber(s, r.t_s);
  for (const JointVector* v : {&r.q_ref, &r.r, &r.a, &r.q_cmd, &r.q})
    for (int j = 0; j < kNumJoints; ++j) {
      s += ',';
      appendNumber(s, (*v)[j]);
    }
  for (const Eigen::Vector3d* p : {&r.ee, &r.ee_ref})
    for (int k = 0; k < 3; ++k) {
      s += ',';
      appendNumber(s, (*p)[k]);
    }
  for (float a : r.att) {
    s += ',';
    appendNumber(s, a);
  }
  s += ',';
  appendInt(s, r.fault);
  for (double us : {r.tick_us, r.retarget_us, r.policy_us, r.sim_us}) {
    s += ',';
    appendNumber(s, zero_timing ? 0.0 : us);
  }
  for (float a : r.attm) {
    s += ',';
    appendNumber(s, a);
  }
  return s;
}

namespace {

using nlohmann::ordered_json;

// What the records sum to beyond the report's own fields: the hand RMSE's and the network
// share's terms, the slow ticks.
struct RecordTotals {
  std::int64_t n_ref = 0, slow = 0, n_policy = 0;
  double net_sq = 0.0, act_sq = 0.0;
};

// The report's metrics from the records: fault counts, latency percentiles, the hand RMSE
// against the reference's feature-extracted trajectory.
RecordTotals measureRecords(const RunOptions& o, const std::vector<TickRecord>& records, RunReport& report) {
  RecordTotals t;
  report.ticks = static_cast<std::int64_t>(records.size());
  report.faults.fill(0);
  std::vector<double> tick_us, retarget_us, policy_us, sim_us;
  double sum_sq = 0.0;
  for (const TickRecord& r : records) {
    // The network's share of the action (docs/evaluate.md): over the ticks the policy ran with a
    // finite action, RMS of its own part over RMS of the action before the limiter.
    if (r.a_net.allFinite() && r.a.allFinite()) {
      t.net_sq += r.a_net.squaredNorm();
      t.act_sq += r.a.squaredNorm();
      ++t.n_policy;
    }
    for (int b = 0; b < kNumControllerFaults; ++b)
      if (r.fault & (1u << b)) ++report.faults[static_cast<std::size_t>(b)];
    tick_us.push_back(r.tick_us);
    retarget_us.push_back(r.retarget_us);
    policy_us.push_back(r.policy_us);
    sim_us.push_back(r.sim_us);
    if (r.tick_us > o.controller.period_s * 1e6) ++t.slow;
    if (r.ee_ref.allFinite()) {
      sum_sq += (r.ee - r.ee_ref).squaredNorm();
      ++t.n_ref;
    }
  }
  report.overruns = report.faults[5];
  static_assert(kFaultOverrun == 1u << 5, "overrun is fault bit 5");
  report.ee_rmse_m = t.n_ref > 0 ? std::sqrt(sum_sq / static_cast<double>(t.n_ref)) : std::nan("");
  report.tick_us = latencyStats(tick_us);
  report.retarget_us = latencyStats(retarget_us);
  report.policy_us = latencyStats(policy_us);
  report.sim_us = latencyStats(sim_us);
  return t;
}

// summary.json's "lola": the LoLA backend's counters and round trips, null on the ODE arm.
ordered_json lolaJson(const RunOptions& o, const LoopTotals& totals) {
  if (!totals.lola) return nullptr;
  const LolaCounters& c = totals.lola_counters;
  std::vector<double> rtt_us;
  rtt_us.reserve(totals.lola_latency_ns.size());
  for (std::int64_t ns : totals.lola_latency_ns) rtt_us.push_back(static_cast<double>(ns) * 1e-3);
  return {{"socket", totals.lola_socket},
          {"cycles", c.cycles},
          {"late", c.late},
          {"late_descheduled", c.late_descheduled},
          {"malformed", c.malformed},
          {"gaps", c.gaps},
          {"hot_cycles", c.hot_cycles},
          {"tracking_cycles", c.tracking_cycles},
          {"io_thread", o.lola.io_thread},
          {"io_thread_scheduling", totals.lola_io_scheduling.empty() ? ordered_json(nullptr)
                                                                     : ordered_json(totals.lola_io_scheduling)},
          {"overrun_ticks", c.overrun_ticks},
          {"warm", c.before_tick_calls > 0},
          {"warm_skipped", c.before_tick_skipped},
          {"warm_us_mean", c.before_tick_calls > 0 ? ordered_json(1e-3 * static_cast<double>(c.before_tick_ns) /
                                                                  static_cast<double>(c.before_tick_calls))
                                                   : ordered_json(nullptr)},
          {"io_allocations", c.io_allocations >= 0 ? ordered_json(c.io_allocations) : ordered_json(nullptr)},
          {"round_trip_us", statsJson(latencyStats(rtt_us))},
          {"stop", totals.stop == RobotStop::kLinkLost ? "link_lost"
                   : totals.stop == RobotStop::kSignal ? "signal"
                                                       : "end_of_run"}};
}

// summary.json (docs/nao_rt.md), in its key order.
ordered_json summaryJson(const RunOptions& o, const PreparedRun& p, const LoopTotals& totals, const RunReport& report,
                         const RecordTotals& t, const AttentionFileSummary& attention) {
  ordered_json j;
  j["ticks"] = report.ticks;
  j["period_s"] = o.controller.period_s;
  j["duration_s"] = static_cast<double>(report.ticks) * o.controller.period_s;
  j["overruns"] = report.overruns;
  ordered_json faults = ordered_json::object();
  for (int b = 0; b < kNumControllerFaults; ++b)
    faults[kControllerFaultNames[static_cast<std::size_t>(b)]] = report.faults[static_cast<std::size_t>(b)];
  j["faults"] = faults;
  j["allocations_after_activate"] =
      totals.allocations >= 0 ? ordered_json(totals.allocations) : ordered_json(nullptr);
  j["tick_us"] = statsJson(report.tick_us);
  j["retarget_us"] = statsJson(report.retarget_us);
  j["policy_us"] = statsJson(report.policy_us);
  j["sim_us"] = statsJson(report.sim_us);
  j["slow_ticks"] = t.slow;
  j["ee_rmse_m"] = numberOrNull(report.ee_rmse_m);
  j["ee_rmse_ticks"] = t.n_ref;
  j["network_share"] =
      t.n_policy > 0 && t.act_sq > 0.0 ? ordered_json(std::sqrt(t.net_sq / t.act_sq)) : ordered_json(nullptr);
  j["policy_ticks"] = t.n_policy;
  // The pose the arm started from at rest (a(−1) = 0): a model start, --start-pose, or a recorded
  // reference's first target pose.
  j["start_q"] = std::vector<double>(p.q_start.data(), p.q_start.data() + kNumJoints);
  if (p.spec.kind == ReferenceKind::kNone) {
    j["start_name"] = p.start_index >= 0 ? ordered_json(p.start_name) : ordered_json(nullptr);
    j["start_index"] = p.start_index >= 0 ? ordered_json(p.start_index) : ordered_json(nullptr);
    // The training demonstration whose code the run followed (a model with run codes).
    j["run_code"] = totals.run_code.empty() ? ordered_json(nullptr) : ordered_json(totals.run_code);
  }
  if (!totals.action_law.empty()) j["action_law"] = totals.action_law;
  j["model"] = {{"path", p.model_source},
                {"checksum", hex64(p.model.checksum)},
                {"conditioning", conditioningName(p.model.header.conditioning)},
                {"chunk", p.model.header.arch.chunk},
                {"precision", weightPrecisionName(p.precision)},
                {"kernel", policyKernelName(totals.kernel)}};
  j["reference"] = p.description;
  j["retarget"] = {{"priority", retargetPriorityName(p.model_spec.retarget.priority)},
                   {"lambda_q", p.model_spec.retarget.lambda_q},
                   {"posture_weights", std::vector<double>(p.model_spec.retarget.posture_weights.data(),
                                                           p.model_spec.retarget.posture_weights.data() + kNumJoints)}};
  j["movement"] = p.spec.movement;
  j["realtime"] = o.realtime;
  if (o.realtime) {
    j["realtime_scheduling"] = totals.realtime_scheduling;
    j["skipped_periods"] = totals.skipped_periods;
  }
  j["zero_timing"] = o.zero_timing;
  j["robot"] = totals.lola ? "lola" : "ode";
  j["lola"] = lolaJson(o, totals);
  // The live source's counters, one per failure kind, and its latency (docs/formats.md "Live
  // camera summary"); its reader thread's allocations from activate to deactivate.
  if (p.live != nullptr) {
    const std::optional<std::int64_t> reader =
        totals.reader_allocations >= 0 ? std::optional<std::int64_t>(totals.reader_allocations) : std::nullopt;
    j["camera"] = ordered_json::parse(p.live->camera().summaryJson(reader).dump());
  } else {
    j["camera"] = nullptr;
  }
  j["wall_s"] = totals.wall_s;
  j["attention"] = {{"file", !o.log_dir.empty() ? ordered_json("attention.bin") : ordered_json(nullptr)},
                    {"shm", o.attention_shm.empty() ? ordered_json(nullptr) : ordered_json(o.attention_shm)},
                    {"records_written", attention.records_written},
                    {"first_record", attention.first_record},
                    {"record_count", attention.record_count}};
  return j;
}

// The live camera's lines of the printed summary.
void printCamera(const LiveSource& live, std::ostream& s) {
  const LiveCameraCounters c = live.camera().counters();
  const nao::LatencyStats l = live.camera().latencyStats();
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "  camera       %llu frames (%llu with nobody), %llu skeletons taken; latency p50 %.1f ms, p99 %.1f ms\n",
                static_cast<unsigned long long>(c.frames_complete + c.frames_incomplete),
                static_cast<unsigned long long>(c.frames_no_person), static_cast<unsigned long long>(c.takes_fresh),
                l.p50_ms, l.p99_ms);
  s << buf;
  std::string failures;
  for (const auto& [name, n] :
       {std::pair{"files_malformed", c.files_malformed}, std::pair{"files_late", c.files_late},
        std::pair{"frames_skipped", c.frames_skipped}, std::pair{"folder_gone", c.folder_gone},
        std::pair{"camera_stopped", c.camera_stopped}, std::pair{"capture_restarts", c.capture_restarts},
        std::pair{"watch_overflows", c.watch_overflows}, std::pair{"reader_errors", c.reader_errors}})
    if (n > 0) failures += (failures.empty() ? "" : ", ") + std::string(name) + " " + std::to_string(n);
  s << "               camera failures " << (failures.empty() ? "none" : failures) << "\n";
}

// The human summary nao_rt prints after a run.
std::string printedSummary(const RunOptions& o, const PreparedRun& p, const LoopTotals& totals, const RunReport& report,
                           const RecordTotals& t, const AttentionFileSummary& attention) {
  std::ostringstream s;
  char buf[256];
  std::snprintf(buf, sizeof buf, "  ticks        %lld (%.1f s simulated, %.2f s wall, %s)\n",
                static_cast<long long>(report.ticks), static_cast<double>(report.ticks) * o.controller.period_s,
                totals.wall_s, o.realtime ? "real time" : "back to back");
  s << buf;
  std::string fault_text;
  for (int b = 0; b < kNumControllerFaults; ++b)
    if (report.faults[static_cast<std::size_t>(b)] > 0)
      fault_text += (fault_text.empty() ? "" : ", ") + std::string(kControllerFaultNames[static_cast<std::size_t>(b)]) +
                    " " + std::to_string(report.faults[static_cast<std::size_t>(b)]);
  s << "  faults       " << (fault_text.empty() ? "none" : fault_text) << "\n";
  if (t.n_ref > 0) {
    std::snprintf(buf, sizeof buf, "  ee RMSE      %.2f mm against the reference's feature-extracted trajectory (%lld ticks)\n",
                  report.ee_rmse_m * 1e3, static_cast<long long>(t.n_ref));
    s << buf;
  }
  s << "  tick         p50 " << millis(report.tick_us.p50) << ", p99 " << millis(report.tick_us.p99) << ", max "
    << millis(report.tick_us.max) << " (policy p99 " << millis(report.policy_us.p99) << ", overruns "
    << report.overruns << ")\n";
  if (p.live != nullptr) printCamera(*p.live, s);
  s << "  allocations  "
    << (totals.allocations >= 0 ? std::to_string(totals.allocations) + " after activate (control thread)"
                                : std::string("not counted"));
  if (totals.lola && totals.lola_counters.io_allocations >= 0)
    s << "; LoLA I/O thread " << totals.lola_counters.io_allocations;
  if (totals.reader_allocations >= 0) s << "; camera reader thread " << totals.reader_allocations;
  s << "\n";
  const fs::path dir(o.log_dir);
  if (!o.log_dir.empty())
    s << "  files        " << (dir / "ticks.csv").string() << ", " << (dir / "attention.bin").string() << " ("
      << attention.record_count << " records), " << (dir / "summary.json").string() << "\n";
  else
    s << "  files        none (--log DIR writes ticks.csv, attention.bin and summary.json)\n";
  return s.str();
}

}  // namespace

void finishRun(const RunOptions& o, const PreparedRun& p, const std::vector<TickRecord>& records,
               const AttentionRingView& ring, const LoopTotals& totals, std::ostream& out, RunReport& report) {
  report.allocations_after_activate = totals.allocations;
  const RecordTotals t = measureRecords(o, records, report);
  const bool logging = !o.log_dir.empty();
  const fs::path dir(o.log_dir);
  AttentionFileSummary attention;
  attention.records_written = recordsWritten(*ring.header);
  if (logging) {
    std::string csv = ticksCsvHeader() + "\n";
    for (const TickRecord& r : records) csv += ticksCsvRow(r, o.zero_timing) + "\n";
    writeText(dir / "ticks.csv", csv);
    attention = writeAttentionFile((dir / "attention.bin").string(), ring);
  }
  report.summary_json = summaryJson(o, p, totals, report, t, attention).dump(2) + "\n";
  if (logging) writeText(dir / "summary.json", report.summary_json);
  out << printedSummary(o, p, totals, report, t, attention);
  out.flush();
}

}  // namespace nao::rt
