// The LoLA robot backend (docs/lola.md): nao_rt --robot lola[:SOCKET] drives a NAO V6
// (or nao_lola_sim) through LoLA's Unix stream socket.
//
// Threads and time: by default everything runs on the control thread (io_thread: see below).
// LoLA is the clock: the robot sends a
// sensor packet every 12 ms and each is answered from the interpolation state; the 10 Hz tick
// runs on the packet that completes 100 ms of LoLA time (cycle counting: 9, 8, 8, ... cycles,
// never the wall clock). By default that one packet is answered after the tick, already toward
// the new command (LoLA applies an answer from the next cycle, so this is the least lag from
// measurement to effect: 12 ms); the other packets are answered at once. With
// answer_after_tick = false every packet is answered at once and the new command goes out one
// cycle later. On this machine the tick fits in a cycle, so by default one thread: no hand-off,
// no lock, nothing to race; a tick longer than a cycle shows up as late answers (counted).
//
// A tick longer than a cycle (the NAO's Atom: 7-22 ms estimated, docs/embedded.md) would hold
// every packet that arrives during it. With io_thread the backend answers on a thread of its own
// (started at construction, parked until activate ends): from the first tick on it receives,
// measures and answers every packet toward the latest command; at each tick boundary it
// publishes the measurement and waits for the tick's command at most io_wait_ms before
// answering (a fast tick's command still goes out with that answer, as on one thread; a slow
// one's with the next). The control thread's command() publishes its command and waits for
// the next boundary. The hand-off is two seqlocks of relaxed atomics (command one way,
// measurement the other) and eventfds to wake the waiting side: no lock, no allocation.
// The I/O thread owns every other member until deactivate joins it; the stop ramp runs on the
// control thread again.
//
// Per cycle: parse the sensor packet (LolaReader, fixed buffers), move the right arm's setpoint
// (LoLA 18-22) toward the tick's command by at most the URDF velocity limit x 12 ms, hold every
// other joint at the position it had at start, write the actuator packet into a preallocated
// buffer and send it. Safe start (activate): command the measured positions back while the
// stiffness ramps from 0 over LolaParams::ramp_s, then move the arm to the start pose at
// to_start_speed, then settle. Safe stop (deactivate, or a signal): hold, ramp the stiffness to 0.
#pragma once

#include "nao/lola.hpp"
#include "nao/robot_backend.hpp"

#include "allocation_probe.hpp"  // runtime/support

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

// The robot build (toolchain/cmake/nao-v6.cmake) answers LoLA on the I/O thread by default: the
// Atom's tick is estimated at 7-22 ms, possibly longer than a cycle (docs/embedded.md).
#ifndef NAO_LOLA_IO_THREAD_DEFAULT
#define NAO_LOLA_IO_THREAD_DEFAULT 0
#endif

namespace nao {

struct LolaParams {
  std::string socket_path = "/tmp/robocup";
  double arm_stiffness = 1.0;        ///< right arm while running (the servo the policy was trained against)
  double hold_stiffness = 0.6;       ///< every other joint: holds its start position
  double ramp_s = 0.6;               ///< safe start: stiffness 0 -> nominal over this long (>= 0.5 s)
  double to_start_speed_rad_s = 0.5; ///< then the arm moves to the controller's start pose this fast
  double settle_s = 0.3;             ///< and rests there this long before the first tick
  double stop_ramp_s = 0.6;          ///< safe stop: stiffness -> 0 over this long
  double hot_c = 75.0;               ///< joint temperature above which its stiffness is scaled
  double hot_stiffness_scale = 0.5;
  double tracking_error_rad = 0.35;  ///< right-arm |measured - previous cycle's command| above this: fault
  /// The packet that ends a tick is answered after the tick, already toward the new command
  /// (one cycle less lag; that answer waits for the tick's work). false: every packet is
  /// answered at once and the new command goes out with the next packet's answer.
  bool answer_after_tick = true;
  /// Answer on a thread of the backend's own (see the top of this file). With
  /// answer_after_tick the packet that ends a tick waits for the tick's command at most
  /// io_wait_ms after it came (then it is answered toward the old one); every other packet is
  /// answered at once.
  bool io_thread = NAO_LOLA_IO_THREAD_DEFAULT != 0;
  double io_wait_ms = 4.0;
  /// Counts the I/O thread's allocations from the first tick to deactivate (io_thread only).
  AllocationProbe* io_probe = nullptr;
  /// One thread only: called on the control thread once per tick in the idle time before the
  /// packet that ends the tick, before_tick_lead_ms before that packet is due (a cycle after the
  /// previous one); skipped if the packet comes first (nao_rt: warmPolicy, so the tick does not
  /// read its weights from memory, docs/lola.md). Must be real-time safe and take less than the
  /// lead; its time is counted in LolaCounters::before_tick_ns.
  void (*before_tick)(void* context) = nullptr;
  void* before_tick_context = nullptr;
  double before_tick_lead_ms = 1.5;
  int gap_cycles = 2;                ///< no packet for more than this many cycles: packet-gap fault
  int link_lost_cycles = 84;         ///< no packet for this many cycles (~1 s): link lost, stop
  std::size_t latency_capacity = 1 << 16;  ///< per-cycle round-trip samples kept (summary, bench)
};

/// Counters of a LoLA run (summary.json "lola").
struct LolaCounters {
  std::int64_t cycles = 0;     ///< sensor packets answered
  std::int64_t late = 0;       ///< answered after their cycle (the packet waited for us)
  /// of those, the answers whose thread spent under a cycle of its own CPU time over the delay:
  /// it waited for a CPU (the machine's load), not for its work
  std::int64_t late_descheduled = 0;
  std::int64_t malformed = 0;  ///< packets skipped: not MessagePack, wrong keys or lengths
  std::int64_t gaps = 0;       ///< times no packet came for more than gap_cycles
  std::int64_t hot_cycles = 0; ///< cycles with a joint above hot_c
  std::int64_t tracking_cycles = 0;  ///< cycles with a tracking error
  std::int64_t io_allocations = -1;  ///< the I/O thread's allocations after activate (-1: not counted)
  std::int64_t overrun_ticks = 0;    ///< io_thread: ticks whose command came after the next boundary
  std::int64_t before_tick_calls = 0;  ///< LolaParams::before_tick calls
  std::int64_t before_tick_ns = 0;     ///< and their total time
  std::int64_t before_tick_skipped = 0;  ///< ticks whose packet came before the hook's time
};

/// Installs SIGINT/SIGTERM handlers that ask a running LolaBackend for a safe stop (and make
/// blocking waits return). Configure time.
void installLolaStopSignals();

class LolaBackend final : public RobotBackend {
 public:
  /// Connects to the LoLA socket (configure time). Throws std::runtime_error naming the path
  /// when it cannot connect.
  LolaBackend(const ArmModel& arm, const LolaParams& params);
  ~LolaBackend() override;
  LolaBackend(const LolaBackend&) = delete;
  LolaBackend& operator=(const LolaBackend&) = delete;

  const JointVector& activate(const JointVector& q0) override;
  const JointVector& measured() const override { return threaded_ ? ctl_.q : q_meas_; }
  const JointVector& command(const JointVector& q_cmd) override;
  std::uint32_t faults() const override { return threaded_ ? ctl_.faults : faults_; }
  std::int64_t waitNs() const override { return threaded_ ? ctl_.wait_ns : wait_ns_; }
  RobotStop stopReason() const override { return threaded_ ? ctl_.stop : stop_; }
  void deactivate() override;
  bool pacesTicks() const override { return true; }

  /// The LoLA socket connected to.
  const std::string& socketPath() const { return params_.socket_path; }
  const LolaCounters& counters() const { return counters_; }
  /// Round-trip time of each answered cycle (sensor packet complete -> actuator packet sent), ns.
  const std::vector<std::int64_t>& latenciesNs() const { return latency_ns_; }
  /// The I/O thread's scheduling policy and priority ("SCHED_FIFO 50", "SCHED_OTHER 0"); empty
  /// without one. It inherits the thread's that constructed the backend. Configure time.
  std::string ioThreadScheduling();

 private:
  enum class Phase { kRamp, kToStart, kSettle, kRun, kStop };
  bool cycle(bool defer);       // waits for, parses and (unless defer) answers one packet; false: stopped
  bool receive();               // one complete packet into reader_; false: stopped
  void measure();               // the packet's measurement: q_meas_, tracking
  void respond(std::int64_t t_in_ns, bool waited);  // this cycle's setpoint and stiffness, sent
  void failLink();
  void beforeTickPacket();      // waits until the lead before the tick's packet, calls before_tick
  void ioMain();                // the I/O thread (io_thread)
  void publishTick();           // I/O thread: the tick boundary's measurement to the control thread
  const JointVector& commandThreaded(const JointVector& q_cmd);

  // A joint vector handed between the two threads without a lock: one writer, readers retry
  // (seqlock of relaxed atomics; the version is odd while a write is in progress).
  class JointSeqlock {
   public:
    void store(const JointVector& q) noexcept;
    /// A complete value into q and its version; false if a write was in progress (q partly set).
    bool tryLoad(JointVector& q, std::uint64_t& version) const noexcept;
    std::uint64_t version() const noexcept { return seq_.load(std::memory_order_acquire); }

   private:
    std::atomic<std::uint64_t> seq_{0};
    std::array<std::atomic<double>, kNumJoints> q_{};
  };

  // The control thread's view while the I/O thread runs (io_thread).
  struct TickView {
    JointVector q = JointVector::Zero();
    std::uint32_t faults = 0;
    std::int64_t wait_ns = 0;
    RobotStop stop = RobotStop::kNone;
  };

  const ArmModel& arm_;
  LolaParams params_;
  int fd_ = -1;
  lola::LolaReader reader_{lola::PacketKind::kSensor};
  lola::ActuatorPacket out_{};
  std::array<char, 16384> rx_{};
  std::size_t rx_len_ = 0;
  std::int64_t rx_pending_since_ns_ = 0;  // when the incomplete bytes in rx_ arrived
  std::array<char, lola::kMaxPacketBytes> tx_{};

  Phase phase_ = Phase::kRamp;
  bool have_start_ = false;
  std::array<float, lola::kNumLolaJoints> start_position_{};
  JointVector q_meas_ = JointVector::Zero();
  JointVector setpoint_ = JointVector::Zero();   // right arm, what the last packet commanded
  JointVector target_ = JointVector::Zero();     // the tick's command / the start pose
  JointVector q_start_ = JointVector::Zero();
  double stiffness_scale_ = 0.0;                 // ramp factor 0..1
  int phase_cycles_ = 0;
  std::int64_t run_cycles_ = 0;
  std::int64_t ticks_ = 0;
  std::int64_t last_packet_ns_ = 0;
  std::int64_t last_send_ns_ = 0;
  std::int64_t last_send_cpu_ns_ = 0;    // this thread's CPU time at the last send
  bool in_gap_ = false;
  bool pending_ = false;                 // the last packet is not answered yet (tick boundary)
  std::int64_t pending_t_in_ns_ = 0;
  bool pending_waited_ = false;
  std::int64_t cpu_in_ns_ = 0;           // this thread's CPU time when the packet to answer came
  std::uint32_t faults_ = 0;
  std::int64_t wait_ns_ = 0;
  RobotStop stop_ = RobotStop::kNone;
  LolaCounters counters_;
  std::vector<std::int64_t> latency_ns_;

  // io_thread: the hand-off. Command: control -> I/O; tick: I/O -> control.
  std::thread io_;
  int go_fd_ = -1;    // eventfd: control -> I/O, wakes the parked thread (io_go_ or io_quit_ says why)
  int tick_fd_ = -1;  // eventfd: I/O -> control, one count per tick boundary (or the stop)
  int cmd_fd_ = -1;   // eventfd: control -> I/O, a new command
  bool threaded_ = false;  // control thread only: the I/O thread owns the LoLA state
  TickView ctl_;
  std::atomic<bool> io_quit_{false};
  std::atomic<bool> io_go_{false};  // activate handed over (release; the I/O thread acquires)
  bool in_io_thread_ = false;       // I/O thread only: inside its run loop
  JointSeqlock cmd_;   // the latest command
  JointSeqlock tick_;  // the measurement of the latest tick boundary
  std::atomic<std::uint32_t> tick_faults_{0};
  std::atomic<int> tick_stop_{0};
  std::atomic<std::int64_t> tick_index_{0};  // tick boundaries published
  std::int64_t ctl_ticks_seen_ = 0;          // control thread: boundaries consumed
  std::int64_t ctl_overruns_ = 0;            // control thread: commands published after their boundary
};

}  // namespace nao
