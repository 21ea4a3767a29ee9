#include "nao/lola_backend.hpp"

#include "nao/controller.hpp"

#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <stdexcept>

namespace nao {
namespace {

// CPU time of the calling thread: what separates a late answer the thread's own work made from
// one it spent waiting for a CPU.
std::int64_t threadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Lock-free, so async-signal-safe, and read by the I/O thread too (--lola-io-thread).
std::atomic<int> g_stop_signal{0};
static_assert(std::atomic<int>::is_always_lock_free);

extern "C" void onStopSignal(int) { g_stop_signal.store(1, std::memory_order_relaxed); }


void signalFd(int fd) {
  const std::uint64_t one = 1;
  while (::write(fd, &one, sizeof one) < 0 && errno == EINTR) {
  }
}

void waitFd(int fd) {
  std::uint64_t n = 0;
  while (::read(fd, &n, sizeof n) < 0 && errno == EINTR) {
  }
}

int cyclesFor(double seconds) {
  return std::max(1, static_cast<int>(std::ceil(seconds * 1e9 / static_cast<double>(lola::kCycleNs) - 1e-9)));
}

// Bytes that stay incomplete this long are not the start of a packet (the robot writes each
// packet at once): dropped as malformed so the stream resynchronises on the next packet.
constexpr std::int64_t kStaleBytesNs = lola::kCycleNs / 2;

}  // namespace

void installLolaStopSignals() {
  struct sigaction sa {};
  sa.sa_handler = onStopSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a blocking poll returns EINTR and the loop sees the flag
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // A robot that closes the socket while we write must not kill us: write() returns EPIPE.
  std::signal(SIGPIPE, SIG_IGN);
}

LolaBackend::LolaBackend(const ArmModel& arm, const LolaParams& params) : arm_(arm), params_(params) {
  if (params_.ramp_s < 0.5) throw std::invalid_argument("lola: the stiffness ramp must last at least 0.5 s");
  sockaddr_un addr{};
  if (params_.socket_path.empty() || params_.socket_path.size() >= sizeof(addr.sun_path))
    throw std::invalid_argument("lola: socket path '" + params_.socket_path + "' is empty or too long");
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw std::runtime_error(std::string("lola: socket(): ") + std::strerror(errno));
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, params_.socket_path.c_str(), params_.socket_path.size());
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error("lola: cannot connect to '" + params_.socket_path + "': " + std::strerror(e) +
                             " (is LoLA, or nao_lola_sim, running?)");
  }
  latency_ns_.reserve(params_.latency_capacity);
  out_.sonar = {1.0f, 1.0f};
  if (params_.io_thread) {
    go_fd_ = ::eventfd(0, EFD_CLOEXEC);
    tick_fd_ = ::eventfd(0, EFD_CLOEXEC);
    cmd_fd_ = ::eventfd(0, EFD_CLOEXEC);
    // The destructor does not run for a constructor that throws: close what is open here.
    auto closeAll = [this] {
      for (int f : {go_fd_, tick_fd_, cmd_fd_, fd_})
        if (f >= 0) ::close(f);
    };
    if (go_fd_ < 0 || tick_fd_ < 0 || cmd_fd_ < 0) {
      const int e = errno;
      closeAll();
      throw std::runtime_error(std::string("lola: eventfd(): ") + std::strerror(e));
    }
    try {
      io_ = std::thread(&LolaBackend::ioMain, this);  // parked until activate hands over
    } catch (...) {
      closeAll();
      throw;
    }
  }
}

std::string LolaBackend::ioThreadScheduling() {
  if (!io_.joinable()) return {};
  int policy = 0;
  sched_param param{};
  if (pthread_getschedparam(io_.native_handle(), &policy, &param) != 0) return "unknown";
  const char* name = policy == SCHED_FIFO ? "SCHED_FIFO" : policy == SCHED_RR ? "SCHED_RR" : "SCHED_OTHER";
  return std::string(name) + " " + std::to_string(param.sched_priority);
}

LolaBackend::~LolaBackend() {
  if (io_.joinable()) {
    io_quit_.store(true, std::memory_order_release);
    signalFd(go_fd_);
    io_.join();
  }
  for (int f : {go_fd_, tick_fd_, cmd_fd_, fd_})
    if (f >= 0) ::close(f);
}

void LolaBackend::failLink() {
  stop_ = RobotStop::kLinkLost;
  faults_ |= kFaultRobotLinkLost | kFaultSafeStop;
}

bool LolaBackend::receive() {
  for (;;) {
    if (rx_len_ > 0) {
      const lola::ParseResult r = reader_.parse(rx_.data(), rx_len_);
      if (r.status == lola::ParseStatus::kComplete || r.status == lola::ParseStatus::kBadContent) {
        std::memmove(rx_.data(), rx_.data() + r.consumed, rx_len_ - r.consumed);
        rx_len_ -= r.consumed;
        rx_pending_since_ns_ = monotonicNs();
        if (r.status == lola::ParseStatus::kComplete) return true;
        ++counters_.malformed;
        faults_ |= kFaultRobotMalformedPacket;
        continue;
      }
      if (r.status == lola::ParseStatus::kBadSyntax || rx_len_ == rx_.size()) {
        rx_len_ = 0;
        ++counters_.malformed;
        faults_ |= kFaultRobotMalformedPacket;
        continue;
      }
      // Incomplete: wait for the rest, unless it has been waiting too long already.
      if (monotonicNs() - rx_pending_since_ns_ > kStaleBytesNs) {
        rx_len_ = 0;
        ++counters_.malformed;
        faults_ |= kFaultRobotMalformedPacket;
      }
    }
    // deactivate asked the I/O thread to hand the socket back: do not wait for more packets.
    if (in_io_thread_ && io_quit_.load(std::memory_order_acquire)) return false;
    if (g_stop_signal.load(std::memory_order_relaxed) != 0) {
      stop_ = RobotStop::kSignal;
      faults_ |= kFaultSafeStop;
      return false;
    }
    // Wait at most until the next thing to check: the gap threshold, link loss, or stale bytes.
    const std::int64_t t0 = monotonicNs();
    const std::int64_t since = t0 - last_packet_ns_;
    const std::int64_t gap_ns = (params_.gap_cycles + 1) * lola::kCycleNs;
    if (have_start_ && since > gap_ns && !in_gap_) {
      in_gap_ = true;
      ++counters_.gaps;
    }
    if (in_gap_) faults_ |= kFaultRobotPacketGap;
    if (have_start_ && since > params_.link_lost_cycles * lola::kCycleNs) {
      failLink();
      return false;
    }
    std::int64_t timeout_ns = lola::kCycleNs;
    if (have_start_ && !in_gap_) timeout_ns = std::max<std::int64_t>(1'000'000, gap_ns - since + 500'000);
    if (rx_len_ > 0) timeout_ns = std::min(timeout_ns, std::max<std::int64_t>(1'000'000, kStaleBytesNs));
    pollfd pfd{fd_, POLLIN, 0};
    const int pr = ::poll(&pfd, 1, static_cast<int>((timeout_ns + 999'999) / 1'000'000));
    wait_ns_ += monotonicNs() - t0;
    if (pr < 0) {
      if (errno == EINTR) continue;
      failLink();
      return false;
    }
    if (pr == 0) continue;
    if (rx_len_ == 0) rx_pending_since_ns_ = monotonicNs();
    const ssize_t n = ::recv(fd_, rx_.data() + rx_len_, rx_.size() - rx_len_, MSG_DONTWAIT);
    if (n == 0) {  // the robot closed the socket
      failLink();
      return false;
    }
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) continue;
      failLink();
      return false;
    }
    rx_len_ += static_cast<std::size_t>(n);
  }
}

bool LolaBackend::cycle(bool defer) {
  if (stop_ != RobotStop::kNone) return false;
  const std::int64_t wait_before = wait_ns_;
  for (;;) {
    if (!receive()) return false;
    // Non-finite positions are a broken packet, not a measurement (never fed to the arm).
    bool finite = true;
    for (float x : reader_.sensor().position) finite = finite && std::isfinite(x);
    if (finite) break;
    ++counters_.malformed;
    faults_ |= kFaultRobotMalformedPacket;
  }
  const std::int64_t t_in = monotonicNs();
  cpu_in_ns_ = threadCpuNs();
  // The packet waited for us (no blocking wait was needed) and the previous answer is more than
  // a cycle and a half ago: this answer comes after the packet's cycle ended.
  const bool waited = wait_ns_ - wait_before > 200'000;
  last_packet_ns_ = t_in;
  in_gap_ = false;
  measure();
  if (defer) {
    pending_ = true;
    pending_t_in_ns_ = t_in;
    pending_waited_ = waited;
  } else {
    respond(t_in, waited);
  }
  return stop_ == RobotStop::kNone;
}

void LolaBackend::measure() {
  ++phase_cycles_;
  const lola::SensorPacket& s = reader_.sensor();
  if (!have_start_) {
    start_position_ = s.position;
    have_start_ = true;
  }
  for (int j = 0; j < kNumJoints; ++j)
    q_meas_[j] = static_cast<double>(s.position[static_cast<std::size_t>(lola::kRightArmLolaIndex[j])]);

  // Tracking: the measurement against what the previous cycle commanded (applied from then on).
  if (phase_ == Phase::kRun) {
    bool far = false;
    for (int j = 0; j < kNumJoints; ++j) far = far || std::abs(q_meas_[j] - setpoint_[j]) > params_.tracking_error_rad;
    if (far) {
      faults_ |= kFaultTrackingError;
      ++counters_.tracking_cycles;
    }
  }
}

void LolaBackend::respond(std::int64_t t_in_ns, bool waited) {
  pending_ = false;
  const lola::SensorPacket& s = reader_.sensor();
  // Phase and setpoint of this cycle.
  const int ramp_cycles = cyclesFor(params_.ramp_s);
  const double dt = static_cast<double>(lola::kCycleNs) * 1e-9;
  auto stepToward = [&](const JointVector& goal, const JointVector& v) {
    bool there = true;
    for (int j = 0; j < kNumJoints; ++j) {
      const double step = v[j] * dt;
      if (!std::isfinite(goal[j])) continue;  // never send a non-finite target: hold
      if (std::abs(goal[j] - setpoint_[j]) <= step)
        setpoint_[j] = goal[j];
      else
        setpoint_[j] += goal[j] > setpoint_[j] ? step : -step;
      there = there && setpoint_[j] == goal[j];
    }
    return there;
  };
  switch (phase_) {
    case Phase::kRamp:
      if (phase_cycles_ == 1) setpoint_ = q_meas_;  // read the positions, command them back
      stiffness_scale_ = std::min(1.0, static_cast<double>(phase_cycles_) / ramp_cycles);
      break;
    case Phase::kToStart:
      stepToward(q_start_, JointVector::Constant(params_.to_start_speed_rad_s));
      break;
    case Phase::kSettle:
    case Phase::kRun:
      stepToward(target_, arm_.v_max);
      break;
    case Phase::kStop: {
      const int stop_cycles = cyclesFor(params_.stop_ramp_s);
      stiffness_scale_ = std::min(stiffness_scale_, std::max(0.0, 1.0 - static_cast<double>(phase_cycles_) / stop_cycles));
      break;
    }
  }

  // Positions: every joint at its start except the right arm; stiffness with hot joints scaled.
  out_.position = start_position_;
  for (int j = 0; j < kNumJoints; ++j)
    out_.position[static_cast<std::size_t>(lola::kRightArmLolaIndex[j])] = static_cast<float>(setpoint_[j]);
  bool hot = false;
  for (int i = 0; i < lola::kNumLolaJoints; ++i) {
    double k = params_.hold_stiffness;
    for (int j = 0; j < kNumJoints; ++j)
      if (lola::kRightArmLolaIndex[j] == i) k = params_.arm_stiffness;
    if (s.temperature[static_cast<std::size_t>(i)] > params_.hot_c) {
      hot = true;
      k *= params_.hot_stiffness_scale;
    }
    out_.stiffness[static_cast<std::size_t>(i)] = static_cast<float>(k * stiffness_scale_);
  }
  if (hot) {
    faults_ |= kFaultJointHot;
    ++counters_.hot_cycles;
  }

  const std::size_t n = lola::writeActuatorPacket(out_, tx_.data(), tx_.size());
  std::size_t sent = 0;
  while (sent < n) {
    const ssize_t w = ::send(fd_, tx_.data() + sent, n - sent, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      failLink();
      return;
    }
    sent += static_cast<std::size_t>(w);
  }
  const std::int64_t t_out = monotonicNs();
  ++counters_.cycles;
  if (latency_ns_.size() < latency_ns_.capacity()) latency_ns_.push_back(t_out - t_in_ns);
  const std::int64_t cpu_out = threadCpuNs();
  const bool late_in = t_out - t_in_ns > lola::kCycleNs;
  if (late_in || (!waited && last_send_ns_ != 0 && t_out - last_send_ns_ > lola::kCycleNs * 3 / 2)) {
    ++counters_.late;
    if (cpu_out - (late_in ? cpu_in_ns_ : last_send_cpu_ns_) <= lola::kCycleNs) ++counters_.late_descheduled;
  }
  last_send_ns_ = t_out;
  last_send_cpu_ns_ = cpu_out;
}

const JointVector& LolaBackend::activate(const JointVector& q0) {
  faults_ = 0;
  wait_ns_ = 0;
  q_start_ = q0;
  phase_ = Phase::kRamp;
  phase_cycles_ = 0;
  stiffness_scale_ = 0.0;
  const int ramp_cycles = cyclesFor(params_.ramp_s);
  const int settle_cycles = cyclesFor(params_.settle_s);
  while (phase_cycles_ < ramp_cycles)
    if (!cycle(false)) return q_meas_;
  phase_ = Phase::kToStart;
  phase_cycles_ = 0;
  // Move until the setpoint is at the start pose (stepToward in answer), then settle.
  while (setpoint_ != q_start_)
    if (!cycle(false)) return q_meas_;
  phase_ = Phase::kSettle;
  phase_cycles_ = 0;
  target_ = q_start_;
  // The last settle packet is answered by the first command, with the first tick's target.
  while (phase_cycles_ < settle_cycles)
    if (!cycle(phase_cycles_ + 1 == settle_cycles && params_.answer_after_tick && !params_.io_thread)) return q_meas_;
  phase_ = Phase::kRun;
  phase_cycles_ = 0;
  run_cycles_ = 0;
  ticks_ = 0;
  // (A second activate after a threaded run has no I/O thread left: it stays on this one.)
  if (!params_.io_thread || !io_.joinable()) return q_meas_;
  // Hand the socket to the I/O thread: from here on it owns every LoLA member.
  ctl_ = TickView{q_meas_, 0, 0, RobotStop::kNone};
  ctl_ticks_seen_ = 0;
  threaded_ = true;
  io_go_.store(true, std::memory_order_release);  // everything written above happens before the I/O thread's reads
  signalFd(go_fd_);
  return ctl_.q;
}

void LolaBackend::JointSeqlock::store(const JointVector& q) noexcept {
  const std::uint64_t s = seq_.load(std::memory_order_relaxed);
  seq_.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  for (int j = 0; j < kNumJoints; ++j) q_[static_cast<std::size_t>(j)].store(q[j], std::memory_order_relaxed);
  seq_.store(s + 2, std::memory_order_release);
}

bool LolaBackend::JointSeqlock::tryLoad(JointVector& q, std::uint64_t& version) const noexcept {
  const std::uint64_t s1 = seq_.load(std::memory_order_acquire);
  if (s1 % 2 != 0) return false;
  for (int j = 0; j < kNumJoints; ++j) q[j] = q_[static_cast<std::size_t>(j)].load(std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_acquire);
  if (seq_.load(std::memory_order_relaxed) != s1) return false;
  version = s1;
  return true;
}

void LolaBackend::ioMain() {
  while (!io_go_.load(std::memory_order_acquire) && !io_quit_.load(std::memory_order_acquire)) waitFd(go_fd_);
  if (io_quit_.load(std::memory_order_acquire)) return;
  if (params_.io_probe != nullptr) params_.io_probe->start();
  in_io_thread_ = true;
  std::uint64_t cmd_seen = 0;
  const std::int64_t wait_ns = static_cast<std::int64_t>(params_.io_wait_ms * 1e6);
  while (!io_quit_.load(std::memory_order_acquire)) {
    if (!cycle(true)) break;  // received and measured; answered below
    ++run_cycles_;
    if (run_cycles_ * lola::kCycleNs >= (ticks_ + 1) * 100'000'000) {
      // The packet that ends a tick: its measurement goes to the control thread, and (as on one
      // thread) its answer waits for the tick's new command, but never past io_wait_ms: a
      // slower tick's command goes out with the next answer instead.
      ++ticks_;
      const std::uint64_t before = cmd_.version();
      publishTick();
      if (params_.answer_after_tick) {
        const std::int64_t until = pending_t_in_ns_ + wait_ns;
        for (;;) {
          const std::uint64_t now = cmd_.version();
          if (now != before && now % 2 == 0) break;
          const std::int64_t left = until - monotonicNs();
          if (left <= 0 || io_quit_.load(std::memory_order_acquire)) break;
          pollfd pfd{cmd_fd_, POLLIN, 0};
          timespec ts{0, static_cast<long>(std::min<std::int64_t>(left, 999'999'999))};
          if (::ppoll(&pfd, 1, &ts, nullptr) > 0) waitFd(cmd_fd_);
        }
      }
    }
    // The latest command, taken after the packet came (a command published while we waited
    // for it goes out now, not a cycle later). A torn read is retried next cycle.
    JointVector c;
    std::uint64_t v = 0;
    if (cmd_.tryLoad(c, v) && v != cmd_seen) {
      target_ = c;
      cmd_seen = v;
    }
    respond(pending_t_in_ns_, pending_waited_);  // toward target_
    if (stop_ != RobotStop::kNone) break;
  }
  in_io_thread_ = false;
  publishTick();  // the stop (or the quit) wakes a waiting command()
  if (params_.io_probe != nullptr) counters_.io_allocations = params_.io_probe->stop();
}

void LolaBackend::publishTick() {
  tick_.store(q_meas_);
  tick_faults_.fetch_or(faults_, std::memory_order_acq_rel);  // kept until the control thread takes them
  faults_ = 0;
  tick_stop_.store(static_cast<int>(stop_), std::memory_order_release);
  tick_index_.fetch_add(1, std::memory_order_acq_rel);
  signalFd(tick_fd_);
}

const JointVector& LolaBackend::commandThreaded(const JointVector& q_cmd) {
  const std::int64_t t0 = monotonicNs();
  if (ctl_.stop != RobotStop::kNone) {
    ctl_.faults = kFaultSafeStop;
    ctl_.wait_ns = 0;
    return ctl_.q;
  }
  // A boundary passed while this tick was computed: its command is late (the tick ends at the
  // next boundary after the command went out).
  const std::int64_t at_publish = tick_index_.load(std::memory_order_acquire);
  if (at_publish > ctl_ticks_seen_ && tick_stop_.load(std::memory_order_acquire) == 0) ++ctl_overruns_;
  cmd_.store(q_cmd);
  signalFd(cmd_fd_);
  while (tick_index_.load(std::memory_order_acquire) <= at_publish && tick_stop_.load(std::memory_order_acquire) == 0)
    waitFd(tick_fd_);
  ctl_ticks_seen_ = tick_index_.load(std::memory_order_acquire);
  for (std::uint64_t v = 0; !tick_.tryLoad(ctl_.q, v);) {
  }
  ctl_.faults = tick_faults_.exchange(0, std::memory_order_acq_rel);
  ctl_.stop = static_cast<RobotStop>(tick_stop_.load(std::memory_order_acquire));
  ctl_.wait_ns = monotonicNs() - t0;
  return ctl_.q;
}

const JointVector& LolaBackend::command(const JointVector& q_cmd) {
  if (threaded_) return commandThreaded(q_cmd);
  if (ticks_ > 0) faults_ = 0;  // what happened during activate goes onto the first tick
  wait_ns_ = 0;
  if (stop_ != RobotStop::kNone) {
    faults_ |= kFaultSafeStop;
    return q_meas_;
  }
  target_ = q_cmd;
  // The packet the tick's measurement came from is answered now, already toward q_cmd.
  if (pending_) respond(pending_t_in_ns_, pending_waited_);
  // Tick k ends with the packet that completes (k + 1) x 100 ms of LoLA time; it is answered
  // by the next command (or by deactivate).
  ++ticks_;
  const std::int64_t end_ns = ticks_ * 100'000'000;
  while (stop_ == RobotStop::kNone && run_cycles_ * lola::kCycleNs < end_ns) {
    const bool last = (run_cycles_ + 1) * lola::kCycleNs >= end_ns;
    if (last && params_.before_tick != nullptr) beforeTickPacket();
    if (!cycle(last && params_.answer_after_tick)) break;
    ++run_cycles_;
  }
  return q_meas_;
}

void LolaBackend::beforeTickPacket() {
  // The tick's packet is due a cycle after the last one. Wait on the socket until the lead
  // before it, so what the hook brings into the cache is still there when the tick runs (a
  // warm right after the previous answer, 12 ms ahead, kept less of it: docs/lola.md).
  const std::int64_t t0 = monotonicNs();
  const std::int64_t at = last_packet_ns_ + lola::kCycleNs - static_cast<std::int64_t>(params_.before_tick_lead_ms * 1e6);
  if (at > t0) {
    pollfd pfd{fd_, POLLIN, 0};
    const timespec ts{static_cast<time_t>((at - t0) / 1'000'000'000), static_cast<long>((at - t0) % 1'000'000'000)};
    const int pr = ::ppoll(&pfd, 1, &ts, nullptr);
    wait_ns_ += monotonicNs() - t0;
    if (pr != 0) {  // a packet came first (or an error, which receive() handles): do not delay it
      ++counters_.before_tick_skipped;
      return;
    }
  }
  const std::int64_t t1 = monotonicNs();
  params_.before_tick(params_.before_tick_context);
  const std::int64_t spent = monotonicNs() - t1;
  counters_.before_tick_ns += spent;
  ++counters_.before_tick_calls;
  // Work done in the robot's idle time, before the tick's packet: not the tick's (tick_us).
  wait_ns_ += spent;
}

void LolaBackend::deactivate() {
  if (threaded_) {
    // Take the socket back: the I/O thread leaves its loop within a cycle (or has already
    // stopped), and the stop ramp runs here as without it.
    io_quit_.store(true, std::memory_order_release);
    io_.join();
    threaded_ = false;
    counters_.overrun_ticks = ctl_overruns_;
    faults_ = tick_faults_.exchange(0, std::memory_order_acq_rel);  // what the last publish left
  }
  if (stop_ == RobotStop::kLinkLost || fd_ < 0) return;
  // Hold where the arm is commanded now, ramp the stiffness to 0, then one more packet at 0.
  // A signal during the ramp does not interrupt it.
  // A second SIGINT/SIGTERM during the ramp ends it early (the stiffness stays where it got).
  const RobotStop reason = stop_;
  stop_ = RobotStop::kNone;
  g_stop_signal.store(0, std::memory_order_relaxed);
  phase_ = Phase::kStop;
  phase_cycles_ = 0;
  target_ = setpoint_;
  if (pending_) respond(pending_t_in_ns_, pending_waited_);
  const int stop_cycles = cyclesFor(params_.stop_ramp_s);
  while (phase_cycles_ <= stop_cycles)
    if (!cycle(false)) break;
  if (stop_ == RobotStop::kNone) stop_ = reason;
}

}  // namespace nao
