// nao_lola_sim: a simulated NAO V6 that speaks LoLA (docs/lola.md) — the hardware-in-the-loop
// substitute nao_rt --robot lola is tested against.
//
// A LoLA socket server on a Unix stream socket. Every 12 ms on the real clock (absolute
// deadlines, CLOCK_MONOTONIC) it advances the body one cycle and sends the full sensor packet;
// the client's actuator packet, when it comes, is applied from the next cycle:
//  - the right arm (LoLA 18-22) is the ODE arm of sim_arm.hpp, 12 x 1 ms physics steps per
//    cycle with NAO's servo model; stiffness s caps each motor's torque at s x its effort limit,
//    and below kGearHoldStiffness the joint is held by its gearbox (torque cap 0.1 x effort,
//    holding where it is) instead of following the command;
//  - the other 20 joints are not simulated physically: each follows its command with a first-
//    order lag whose rate scales with its stiffness (held where it is at stiffness 0);
//  - everything else in the packet is a plausible constant (a NAO sitting still: gravity on the
//    accelerometer, feet unloaded, 35 °C joints, a 90 % battery).
// Fault injection by flag: drop or delay sensor packets, send garbage or a packet with a wrong
// array length, close the socket, heat a joint. It records every actuator packet it received
// (--log CSV) and a summary (--summary JSON) for the tests and the benchmark.
#include "nao/arm_model.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/controller.hpp"
#include "nao/lola.hpp"
#include "nao/sim_arm.hpp"

#include <CLI/CLI.hpp>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

using nao::JointVector;
using nao::kNumJoints;
namespace lola = nao::lola;
constexpr int kN = lola::kNumLolaJoints;
constexpr double kGearHoldStiffness = 0.1;
constexpr double kAmbientC = 35.0;

volatile std::sig_atomic_t g_quit = 0;
extern "C" void onQuit(int) { g_quit = 1; }

void sleepUntil(std::int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(t_ns % 1'000'000'000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR && g_quit == 0) {
  }
}

/// A sitting NAO: where the joints start (rad), the right arm at nao_rt's home pose.
std::array<float, kN> startPose(const JointVector& arm) {
  std::array<float, kN> p{0.0f,  0.0f,  1.40f, 0.20f,  -1.20f, -0.50f, 0.0f,  // head, left arm
                          0.0f,  0.0f,  -0.90f, 2.10f, -1.20f, 0.0f,          // left leg
                          0.0f,  -0.90f, 2.10f, -1.20f, 0.0f,                 // right leg
                          0.0f,  0.0f,  0.0f,  0.0f,   0.0f,                  // right arm (below)
                          0.25f, 0.25f};                                      // hands
  for (int j = 0; j < kNumJoints; ++j) p[static_cast<std::size_t>(lola::kRightArmLolaIndex[j])] = static_cast<float>(arm[j]);
  return p;
}

struct Injection {
  std::vector<std::string> drop, delay, garbage, bad_length, heat, misread;
  std::int64_t close_at = -1;
};

/// "A:B" pairs of integers / numbers.
bool splitPair(const std::string& s, double& a, double& b) {
  const auto c = s.find(':');
  if (c == std::string::npos) return false;
  try {
    a = std::stod(s.substr(0, c));
    b = std::stod(s.substr(c + 1));
  } catch (...) {
    return false;
  }
  return true;
}

struct Event {
  std::int64_t cycle;
  double value;
  int joint;
};

struct RxRow {
  std::int64_t cycle;     ///< sensor packet this answers
  double latency_us;      ///< sensor packet sent -> this actuator packet complete
  bool in_cycle;          ///< complete before the next cycle's deadline
  lola::ActuatorPacket packet;
};

struct Stats {
  std::int64_t cycles = 0, sent = 0, answered = 0, in_cycle = 0, dropped = 0, delayed = 0, garbage = 0,
               bad_length = 0, malformed_received = 0, extra_answers = 0;
  bool closed_by_injection = false, client_closed = false;
};

/// The command line.
struct Options {
  std::string socket_path, urdf = NAO_DEFAULT_URDF, log_path, summary_path;
  double seconds = 0.0;
  std::vector<double> arm_start = {1.40, -0.20, 1.20, 0.50, 0.00};
  bool apply_at_once = false;
  Injection inj;
};

/// The injected faults as events: the cycle each starts at and its value.
struct Plan {
  std::vector<Event> drops, delays, garbages, bads, heats, misreads;
  std::int64_t close_at = -1;
};

/// -1 when the command line is good, else the exit status (help printed: 0; an error: 2).
int parseOptions(int argc, char** argv, Options& o) {
  Injection& inj = o.inj;
  CLI::App app{
      "nao_lola_sim: a simulated NAO V6 behind a LoLA socket (docs/lola.md): the ODE right arm and 20\n"
      "held joints, a 12 ms cycle on the real clock, fault injection by flag. Serves one client at a\n"
      "time until killed or until --seconds elapse.",
      "nao_lola_sim"};
  app.add_option("--socket", o.socket_path, "Unix socket path to serve (LoLA's is /tmp/robocup)")->required();
  app.add_option("--seconds", o.seconds, "Stop after this long (default: until SIGINT/SIGTERM)")->check(CLI::PositiveNumber);
  app.add_option("--urdf", o.urdf, "Robot description of the simulated arm")->capture_default_str();
  app.add_option("--arm-start", o.arm_start, "Right arm start pose, 5 angles, rad (default: nao_rt's home pose)")
      ->expected(kNumJoints);
  app.add_flag("--apply-at-once", o.apply_at_once,
               "Diagnostics: an answer drives the body from its own cycle instead of the next one\n"
               "(lola.md: the next), i.e. a robot without LoLA's one-cycle transport lag");
  app.add_option("--log", o.log_path,
                 "CSV of every actuator packet received: cycle, latency_us, in_cycle, then Position and\n"
                 "Stiffness of the 25 joints (written at exit)");
  app.add_option("--summary", o.summary_path, "JSON of the counts and round-trip latencies (written at exit)");
  app.add_option("--drop", inj.drop, "CYCLE:N  do not send the sensor packets of N cycles from CYCLE")->type_name("C:N");
  app.add_option("--delay", inj.delay, "CYCLE:MS  send CYCLE's sensor packet MS milliseconds late")->type_name("C:MS");
  app.add_option("--garbage", inj.garbage, "CYCLE:BYTES  send random bytes instead of CYCLE's sensor packet")
      ->type_name("C:B");
  app.add_option("--bad-length", inj.bad_length,
                 "CYCLE:N  for N cycles from CYCLE send a sensor packet whose Position has 24 entries")
      ->type_name("C:N");
  app.add_option("--close-at", inj.close_at, "Close the client's socket at this cycle and exit")->type_name("C");
  app.add_option("--misread", inj.misread,
                 "CYCLE:N  for N cycles from CYCLE, RElbowRoll (LoLA 21) reads 0.5 rad off (a bad\n"
                 "encoder, or an arm held by someone): the client's tracking check must see it")
      ->type_name("C:N");
  app.add_option("--heat", inj.heat, "JOINT:CYCLE  from CYCLE on, LoLA joint JOINT reads 80 degC")->type_name("J:C");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return -1;
}

/// The injection plan from the flags; false (a line on stderr) for a malformed one.
bool makePlan(const Injection& inj, Plan& plan) {
  auto parseList = [](const std::vector<std::string>& in, std::vector<Event>& out, const char* flag) {
    for (const std::string& s : in) {
      double a = 0, b = 0;
      if (!splitPair(s, a, b)) {
        std::cerr << "nao_lola_sim: " << flag << " '" << s << "': expected A:B\n";
        return false;
      }
      out.push_back(Event{static_cast<std::int64_t>(a), b, static_cast<int>(a)});
    }
    return true;
  };
  if (!parseList(inj.drop, plan.drops, "--drop") || !parseList(inj.delay, plan.delays, "--delay") ||
      !parseList(inj.garbage, plan.garbages, "--garbage") || !parseList(inj.bad_length, plan.bads, "--bad-length") ||
      !parseList(inj.heat, plan.heats, "--heat") || !parseList(inj.misread, plan.misreads, "--misread"))
    return false;
  for (Event& h : plan.heats) {  // J:C
    if (h.joint < 0 || h.joint >= kN) {
      std::cerr << "nao_lola_sim: --heat joint must be a LoLA index 0..24\n";
      return false;
    }
    h.cycle = static_cast<std::int64_t>(h.value);
  }
  plan.close_at = inj.close_at;
  return true;
}

/// True when an event's window [cycle, cycle + max(1, value)) holds c; its value into `value`.
bool inWindow(const std::vector<Event>& ev, std::int64_t c, double& value) {
  for (const Event& e : ev)
    if (c >= e.cycle && c < e.cycle + std::max<std::int64_t>(1, static_cast<std::int64_t>(e.value))) {
      value = e.value;
      return true;
    }
  return false;
}

/// True when an event starts at c; its value into `value`.
bool atCycle(const std::vector<Event>& ev, std::int64_t c, double& value) {
  for (const Event& e : ev)
    if (c == e.cycle) {
      value = e.value;
      return true;
    }
  return false;
}

/// The simulated NAO: the ODE right arm, the 20 held joints, what the client last commanded.
struct Body {
  std::unique_ptr<nao::SimModel> model;
  std::unique_ptr<nao::SimData> sim;
  std::array<float, kN> position{};
  std::array<float, kN> applied_pos{}, applied_stiff{};  // stiffness 0 until commanded
  std::array<float, kN> latest_pos{}, latest_stiff{};
  bool have_latest = false;
};

/// One cycle of the body with what was applied: the arm's physics (gearbox hold below
/// kGearHoldStiffness), every other joint's first-order lag toward its command.
void advanceBody(Body& b, double dt) {
  JointVector q_cmd, scale;
  for (int j = 0; j < kNumJoints; ++j) {
    const auto i = static_cast<std::size_t>(lola::kRightArmLolaIndex[j]);
    const double s = b.applied_stiff[i];
    scale[j] = std::max(s, kGearHoldStiffness);
    q_cmd[j] = s < kGearHoldStiffness ? b.sim->q[j] : static_cast<double>(b.applied_pos[i]);
  }
  nao::setSimTorqueScale(*b.model, *b.sim, scale);
  nao::stepSim(*b.model, *b.sim, q_cmd);
  for (int i = 0; i < kN; ++i) {
    const auto u = static_cast<std::size_t>(i);
    const double k = 25.0 * std::clamp<double>(b.applied_stiff[u], 0.0, 1.0);
    b.position[u] += static_cast<float>((b.applied_pos[u] - b.position[u]) * (1.0 - std::exp(-k * dt)));
  }
  for (int j = 0; j < kNumJoints; ++j)
    b.position[static_cast<std::size_t>(lola::kRightArmLolaIndex[j])] = static_cast<float>(b.sim->q[j]);
}

/// The socket and what travels over it.
struct Link {
  int client = -1;
  std::array<char, lola::kMaxPacketBytes> tx{};
  std::array<char, 16384> rx{};
  std::size_t rx_len = 0;
  std::vector<std::int64_t> sent_cycle_queue;  // sensor packets awaiting an answer (cycle numbers)
  std::vector<std::int64_t> sent_time_queue;
};

/// The cycle's sensor packet into link.tx (its bytes into n), or the injected fault instead of
/// it; false when the packet is dropped.
bool sensorBytes(const Plan& plan, std::int64_t cycle, Body& b, lola::SensorPacket& sensor, Link& link,
                 std::mt19937& rng, Stats& st, std::size_t& n) {
  double v = 0;
  sensor.position = b.position;
  if (inWindow(plan.misreads, cycle, v)) sensor.position[21] += 0.5f;
  sensor.stiffness = b.applied_stiff;
  for (const Event& h : plan.heats)
    if (cycle >= h.cycle) sensor.temperature[static_cast<std::size_t>(h.joint)] = 80.0f;
  n = lola::writeSensorPacket(sensor, link.tx.data(), link.tx.size());
  if (inWindow(plan.drops, cycle, v)) {
    ++st.dropped;
    return false;
  }
  if (atCycle(plan.garbages, cycle, v)) {
    n = std::min<std::size_t>(static_cast<std::size_t>(std::max(1.0, v)), link.tx.size());
    for (std::size_t k = 0; k < n; ++k) link.tx[k] = static_cast<char>(rng() & 0xff);
    ++st.garbage;
  } else if (inWindow(plan.bads, cycle, v)) {
    // The same map with Position one entry short: a whole, well-formed message of the wrong shape.
    std::string bytes(link.tx.data(), n);
    const std::string key("\xa8" "Position\xdc\x00\x19", 12);  // fixstr "Position", array16 of 25
    const auto at = bytes.find(key);
    if (at != std::string::npos) {
      bytes[at + 11] = 0x18;                    // 24 entries
      bytes.erase(at + 12 + 4 * 5, 5);          // drop one float32 (5 bytes)
    }
    n = bytes.size();
    std::memcpy(link.tx.data(), bytes.data(), n);
    ++st.bad_length;
  }
  return true;
}

/// Sends n bytes of link.tx and queues the cycle for its answer.
void sendSensor(Link& link, std::size_t n, std::int64_t cycle, Stats& st) {
  const std::int64_t t_sent = nao::monotonicNs();
  std::size_t off = 0;
  while (off < n) {
    const ssize_t w = ::send(link.client, link.tx.data() + off, n - off, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) break;
    off += static_cast<std::size_t>(w);
  }
  ++st.sent;
  link.sent_cycle_queue.push_back(cycle);
  link.sent_time_queue.push_back(t_sent);
}

/// Parses the actuator packets in link.rx: the latest is applied from the next cycle, each
/// answer is matched with the oldest unanswered sensor packet.
void takeAnswers(Link& link, lola::LolaReader& reader, std::int64_t cycle, std::int64_t next_deadline, Body& b,
                 std::vector<RxRow>& rows, std::vector<double>& latencies_us, Stats& st) {
  for (;;) {
    const lola::ParseResult pr = reader.parse(link.rx.data(), link.rx_len);
    if (pr.status == lola::ParseStatus::kIncomplete) {
      if (link.rx_len == link.rx.size()) link.rx_len = 0;
      return;
    }
    if (pr.status == lola::ParseStatus::kBadSyntax) {
      ++st.malformed_received;
      link.rx_len = 0;
      return;
    }
    std::memmove(link.rx.data(), link.rx.data() + pr.consumed, link.rx_len - pr.consumed);
    link.rx_len -= pr.consumed;
    if (pr.status == lola::ParseStatus::kBadContent) {
      ++st.malformed_received;
      continue;
    }
    const std::int64_t t_rx = nao::monotonicNs();
    b.latest_pos = reader.actuator().position;
    b.latest_stiff = reader.actuator().stiffness;
    b.have_latest = true;
    if (link.sent_cycle_queue.empty()) {
      ++st.extra_answers;
      continue;
    }
    const std::int64_t answered_cycle = link.sent_cycle_queue.front();
    const double lat_us = static_cast<double>(t_rx - link.sent_time_queue.front()) * 1e-3;
    link.sent_cycle_queue.erase(link.sent_cycle_queue.begin());
    link.sent_time_queue.erase(link.sent_time_queue.begin());
    const bool in_cycle = answered_cycle == cycle && t_rx < next_deadline;
    ++st.answered;
    if (in_cycle) ++st.in_cycle;
    latencies_us.push_back(lat_us);
    rows.push_back(RxRow{answered_cycle, lat_us, in_cycle, reader.actuator()});
  }
}

/// Reads answers until the cycle's deadline; false when the client closed the socket.
bool readUntil(Link& link, lola::LolaReader& reader, std::int64_t cycle, std::int64_t next_deadline, Body& b,
               std::vector<RxRow>& rows, std::vector<double>& latencies_us, Stats& st) {
  for (;;) {
    const std::int64_t now = nao::monotonicNs();
    if (now >= next_deadline || g_quit != 0) return true;
    pollfd pfd{link.client, POLLIN, 0};
    const int pr = ::poll(&pfd, 1, static_cast<int>(std::max<std::int64_t>(1, (next_deadline - now) / 1'000'000)));
    if (pr <= 0) continue;
    const ssize_t r = ::recv(link.client, link.rx.data() + link.rx_len, link.rx.size() - link.rx_len, MSG_DONTWAIT);
    if (r == 0 || (r < 0 && errno != EAGAIN && errno != EINTR)) return false;
    if (r < 0) continue;
    link.rx_len += static_cast<std::size_t>(r);
    takeAnswers(link, reader, cycle, next_deadline, b, rows, latencies_us, st);
  }
}

/// A NAO sitting still: constant temperatures, currents, IMU, feet, sonar, battery and config.
lola::SensorPacket restingSensor() {
  lola::SensorPacket sensor;
  sensor.temperature.fill(static_cast<float>(kAmbientC));
  sensor.current.fill(0.05f);
  sensor.accelerometer = {0.0f, 0.0f, -9.81f};
  sensor.fsr.fill(0.0f);
  sensor.sonar = {2.55f, 2.55f};
  sensor.battery = {0.9f, -1.2f, 0.0f, 33.0f};
  const char* config[4] = {"P0000074A05S94700017", "6.0.0", "P0000073A03S94600016", "6.0.0"};
  for (int i = 0; i < 4; ++i) std::snprintf(sensor.robot_config[static_cast<std::size_t>(i)].data(), lola::kRobotConfigChars, "%s", config[i]);
  return sensor;
}

/// Serves clients on `server`, one at a time, every 12 ms until SIGINT/SIGTERM, `t_end`, or an
/// injected close; the answers into rows and latencies_us.
void serve(int server, const Options& o, const Plan& plan, Body& b, std::vector<RxRow>& rows,
           std::vector<double>& latencies_us, Stats& st) {
  const std::int64_t t_begin = nao::monotonicNs();
  const std::int64_t t_end = o.seconds > 0 ? t_begin + static_cast<std::int64_t>(o.seconds * 1e9) : INT64_MAX;
  std::mt19937 rng(7);
  lola::SensorPacket sensor = restingSensor();
  Link link;
  lola::LolaReader reader(lola::PacketKind::kActuator);
  std::int64_t cycle = 0;
  std::int64_t next_deadline = 0;
  const double dt = static_cast<double>(lola::kCycleNs) * 1e-9;
  while (g_quit == 0 && nao::monotonicNs() < t_end) {
    if (link.client < 0) {
      pollfd pfd{server, POLLIN, 0};
      if (::poll(&pfd, 1, 50) <= 0) continue;
      link.client = ::accept4(server, nullptr, nullptr, SOCK_CLOEXEC);
      if (link.client < 0) continue;
      next_deadline = nao::monotonicNs();
      link.rx_len = 0;
      link.sent_cycle_queue.clear();
      link.sent_time_queue.clear();
    }

    // 1. The body advances one cycle with what was applied.
    if (o.apply_at_once && b.have_latest) {
      b.applied_pos = b.latest_pos;
      b.applied_stiff = b.latest_stiff;
    }
    if (cycle > 0) advanceBody(b, dt);
    // What the client answered during the last cycle applies from now on (lola.md: from the
    // next cycle), so a sensor packet's answer first moves the body one cycle after it.
    if (b.have_latest) {
      b.applied_pos = b.latest_pos;
      b.applied_stiff = b.latest_stiff;
    }

    // 2. The sensor packet (or the injected fault instead of it).
    if (plan.close_at >= 0 && cycle >= plan.close_at) {
      ::close(link.client);
      link.client = -1;
      st.closed_by_injection = true;
      break;
    }
    std::size_t n = 0;
    const bool send = sensorBytes(plan, cycle, b, sensor, link, rng, st, n);
    double v = 0;
    if (atCycle(plan.delays, cycle, v)) {
      ++st.delayed;
      sleepUntil(nao::monotonicNs() + static_cast<std::int64_t>(v * 1e6));
    }
    if (send) sendSensor(link, n, cycle, st);
    ++st.cycles;
    next_deadline += lola::kCycleNs;

    // 3. Until the next deadline: read answers; the latest is applied from the next cycle.
    if (!readUntil(link, reader, cycle, next_deadline, b, rows, latencies_us, st)) {
      ::close(link.client);
      link.client = -1;
      st.client_closed = true;
      // One client per run in our tests: serve the next one from the same body state.
    }
    ++cycle;
    if (link.client >= 0) sleepUntil(next_deadline);
  }
  if (link.client >= 0) ::close(link.client);
}

/// --log: every actuator packet received, one CSV row each.
void writeLog(const std::string& path, const std::vector<RxRow>& rows) {
  std::ofstream f(path);
  f << "cycle,latency_us,in_cycle";
  for (int i = 0; i < kN; ++i) f << ",pos_" << lola::kLolaJointNames[static_cast<std::size_t>(i)];
  for (int i = 0; i < kN; ++i) f << ",stiff_" << lola::kLolaJointNames[static_cast<std::size_t>(i)];
  f << "\n";
  char buf[64];
  for (const RxRow& r : rows) {
    f << r.cycle << "," << r.latency_us << "," << (r.in_cycle ? 1 : 0);
    for (float x : r.packet.position) {
      std::snprintf(buf, sizeof buf, ",%.9g", static_cast<double>(x));
      f << buf;
    }
    for (float x : r.packet.stiffness) {
      std::snprintf(buf, sizeof buf, ",%.9g", static_cast<double>(x));
      f << buf;
    }
    f << "\n";
  }
}

/// --summary: the counts and the round-trip percentiles (nearest rank) as JSON.
std::string summaryJson(const Stats& st, std::vector<double> latencies_us) {
  std::sort(latencies_us.begin(), latencies_us.end());
  auto pct = [&](double p) {
    if (latencies_us.empty()) return 0.0;
    const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(latencies_us.size())));
    return latencies_us[std::min(latencies_us.size() - 1, k == 0 ? 0 : k - 1)];
  };
  std::ostringstream js;
  js << "{\n  \"cycles\": " << st.cycles << ",\n  \"sent\": " << st.sent << ",\n  \"answered\": " << st.answered
     << ",\n  \"answered_in_cycle\": " << st.in_cycle << ",\n  \"dropped\": " << st.dropped
     << ",\n  \"delayed\": " << st.delayed << ",\n  \"garbage\": " << st.garbage << ",\n  \"bad_length\": " << st.bad_length
     << ",\n  \"malformed_received\": " << st.malformed_received << ",\n  \"extra_answers\": " << st.extra_answers
     << ",\n  \"closed_by_injection\": " << (st.closed_by_injection ? "true" : "false")
     << ",\n  \"client_closed\": " << (st.client_closed ? "true" : "false") << ",\n  \"round_trip_us\": {\"p50\": "
     << pct(0.50) << ", \"p99\": " << pct(0.99) << ", \"max\": " << (latencies_us.empty() ? 0.0 : latencies_us.back())
     << ", \"n\": " << latencies_us.size() << "}\n}\n";
  return js.str();
}

/// The server socket at `path` (shorter than sun_path; a stale one removed), listening; -1 (a
/// line on stderr) if not.
int listenOn(const std::string& path) {
  sockaddr_un addr{};
  const int server = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.c_str(), path.size());
  ::unlink(path.c_str());
  if (server < 0 || ::bind(server, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::listen(server, 1) != 0) {
    std::cerr << "nao_lola_sim: cannot serve '" << path << "': " << std::strerror(errno) << "\n";
    return -1;
  }
  return server;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const int status = parseOptions(argc, argv, o); status >= 0) return status;
  // Configure: the injection plan, the arm, the server socket.
  Plan plan;
  if (!makePlan(o.inj, plan)) return 2;
  nao::SimParams sp;
  sp.substeps_per_tick = static_cast<int>(lola::kCycleNs / 1'000'000);  // 12 x 1 ms
  JointVector q_arm0;
  for (int j = 0; j < kNumJoints; ++j) q_arm0[j] = o.arm_start[static_cast<std::size_t>(j)];
  Body body;
  try {
    body.model = std::make_unique<nao::SimModel>(nao::makeSimModel(nao::loadArmModel(o.urdf), sp));
    q_arm0 = nao::clampToLimits(body.model->arm, q_arm0);
    body.sim = std::make_unique<nao::SimData>(*body.model, q_arm0);
  } catch (const std::exception& e) {
    std::cerr << "nao_lola_sim: " << e.what() << "\n";
    return 1;
  }
  body.position = startPose(q_arm0);
  body.applied_pos = body.latest_pos = body.position;
  if (o.socket_path.size() >= sizeof(sockaddr_un{}.sun_path)) {
    std::cerr << "nao_lola_sim: socket path too long\n";
    return 2;
  }
  const int server = listenOn(o.socket_path);
  if (server < 0) return 1;
  struct sigaction sa {};
  sa.sa_handler = onQuit;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  Stats st;
  std::vector<RxRow> rows;
  rows.reserve(o.seconds > 0 ? static_cast<std::size_t>(o.seconds / 0.012) + 16 : 100000);
  std::vector<double> latencies_us;
  latencies_us.reserve(rows.capacity());
  serve(server, o, plan, body, rows, latencies_us, st);
  ::close(server);
  ::unlink(o.socket_path.c_str());

  if (!o.log_path.empty()) writeLog(o.log_path, rows);
  const std::string summary = summaryJson(st, latencies_us);
  if (!o.summary_path.empty()) std::ofstream(o.summary_path) << summary;
  std::cerr << "nao_lola_sim: " << st.cycles << " cycles, " << st.sent << " sent, " << st.answered << " answered ("
            << st.in_cycle << " within the cycle)\n";
  return 0;
}
