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

}  // namespace

int main(int argc, char** argv) {
  std::string socket_path, urdf = NAO_DEFAULT_URDF, log_path, summary_path;
  double seconds = 0.0;
  std::vector<double> arm_start = {1.40, -0.20, 1.20, 0.50, 0.00};
  Injection inj;
  CLI::App app{
      "nao_lola_sim: a simulated NAO V6 behind a LoLA socket (docs/lola.md): the ODE right arm and 20\n"
      "held joints, a 12 ms cycle on the real clock, fault injection by flag. Serves one client at a\n"
      "time until killed or until --seconds elapse.",
      "nao_lola_sim"};
  app.add_option("--socket", socket_path, "Unix socket path to serve (LoLA's is /tmp/robocup)")->required();
  app.add_option("--seconds", seconds, "Stop after this long (default: until SIGINT/SIGTERM)")->check(CLI::PositiveNumber);
  app.add_option("--urdf", urdf, "Robot description of the simulated arm")->capture_default_str();
  app.add_option("--arm-start", arm_start, "Right arm start pose, 5 angles, rad (default: nao_rt's home pose)")
      ->expected(kNumJoints);
  bool apply_at_once = false;
  app.add_flag("--apply-at-once", apply_at_once,
               "Diagnostics: an answer drives the body from its own cycle instead of the next one\n"
               "(lola.md: the next), i.e. a robot without LoLA's one-cycle transport lag");
  app.add_option("--log", log_path,
                 "CSV of every actuator packet received: cycle, latency_us, in_cycle, then Position and\n"
                 "Stiffness of the 25 joints (written at exit)");
  app.add_option("--summary", summary_path, "JSON of the counts and round-trip latencies (written at exit)");
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
  CLI11_PARSE(app, argc, argv);

  // Configure: the arm, the injection plan, the server socket.
  std::vector<Event> drops, delays, garbages, bads, heats, misreads;
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
  if (!parseList(inj.drop, drops, "--drop") || !parseList(inj.delay, delays, "--delay") ||
      !parseList(inj.garbage, garbages, "--garbage") || !parseList(inj.bad_length, bads, "--bad-length") ||
      !parseList(inj.heat, heats, "--heat") || !parseList(inj.misread, misreads, "--misread"))
    return 2;
  for (Event& h : heats) {  // J:C
    if (h.joint < 0 || h.joint >= kN) {
      std::cerr << "nao_lola_sim: --heat joint must be a LoLA index 0..24\n";
      return 2;
    }
    h.cycle = static_cast<std::int64_t>(h.value);
  }

  nao::SimParams sp;
  sp.substeps_per_tick = static_cast<int>(lola::kCycleNs / 1'000'000);  // 12 x 1 ms
  JointVector q_arm0;
  for (int j = 0; j < kNumJoints; ++j) q_arm0[j] = arm_start[static_cast<std::size_t>(j)];
  std::unique_ptr<nao::SimModel> model;
  std::unique_ptr<nao::SimData> sim;
  try {
    model = std::make_unique<nao::SimModel>(nao::makeSimModel(nao::loadArmModel(urdf), sp));
    q_arm0 = nao::clampToLimits(model->arm, q_arm0);
    sim = std::make_unique<nao::SimData>(*model, q_arm0);
  } catch (const std::exception& e) {
    std::cerr << "nao_lola_sim: " << e.what() << "\n";
    return 1;
  }

  sockaddr_un addr{};
  if (socket_path.size() >= sizeof(addr.sun_path)) {
    std::cerr << "nao_lola_sim: socket path too long\n";
    return 2;
  }
  const int server = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, socket_path.c_str(), socket_path.size());
  ::unlink(socket_path.c_str());
  if (server < 0 || ::bind(server, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::listen(server, 1) != 0) {
    std::cerr << "nao_lola_sim: cannot serve '" << socket_path << "': " << std::strerror(errno) << "\n";
    return 1;
  }
  struct sigaction sa {};
  sa.sa_handler = onQuit;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  const std::int64_t t_begin = nao::monotonicNs();
  const std::int64_t t_end = seconds > 0 ? t_begin + static_cast<std::int64_t>(seconds * 1e9) : INT64_MAX;
  std::mt19937 rng(7);
  Stats st;
  std::vector<RxRow> rows;
  rows.reserve(seconds > 0 ? static_cast<std::size_t>(seconds / 0.012) + 16 : 100000);
  std::vector<double> latencies_us;
  latencies_us.reserve(rows.capacity());

  // Body state.
  std::array<float, kN> position = startPose(q_arm0);
  std::array<float, kN> applied_pos = position, applied_stiff{};  // stiffness 0 until commanded
  std::array<float, kN> latest_pos = position, latest_stiff{};
  bool have_latest = false;
  lola::SensorPacket sensor;
  sensor.temperature.fill(static_cast<float>(kAmbientC));
  sensor.current.fill(0.05f);
  sensor.accelerometer = {0.0f, 0.0f, -9.81f};
  sensor.fsr.fill(0.0f);
  sensor.sonar = {2.55f, 2.55f};
  sensor.battery = {0.9f, -1.2f, 0.0f, 33.0f};
  const char* config[4] = {"P0000074A05S94700017", "6.0.0", "P0000073A03S94600016", "6.0.0"};
  for (int i = 0; i < 4; ++i) std::snprintf(sensor.robot_config[static_cast<std::size_t>(i)].data(), lola::kRobotConfigChars, "%s", config[i]);
  std::array<char, lola::kMaxPacketBytes> tx{};
  std::array<char, 16384> rx{};
  std::size_t rx_len = 0;
  lola::LolaReader reader(lola::PacketKind::kActuator);

  int client = -1;
  std::int64_t cycle = 0;
  std::int64_t next_deadline = 0;
  std::vector<std::int64_t> sent_cycle_queue;  // sensor packets awaiting an answer (cycle numbers)
  std::vector<std::int64_t> sent_time_queue;
  const double dt = static_cast<double>(lola::kCycleNs) * 1e-9;

  auto inWindow = [](const std::vector<Event>& ev, std::int64_t c, double& value) {
    for (const Event& e : ev)
      if (c >= e.cycle && c < e.cycle + std::max<std::int64_t>(1, static_cast<std::int64_t>(e.value))) {
        value = e.value;
        return true;
      }
    return false;
  };
  auto atCycle = [](const std::vector<Event>& ev, std::int64_t c, double& value) {
    for (const Event& e : ev)
      if (c == e.cycle) {
        value = e.value;
        return true;
      }
    return false;
  };

  while (g_quit == 0 && nao::monotonicNs() < t_end) {
    if (client < 0) {
      pollfd pfd{server, POLLIN, 0};
      if (::poll(&pfd, 1, 50) <= 0) continue;
      client = ::accept4(server, nullptr, nullptr, SOCK_CLOEXEC);
      if (client < 0) continue;
      next_deadline = nao::monotonicNs();
      rx_len = 0;
      sent_cycle_queue.clear();
      sent_time_queue.clear();
    }

    // 1. The body advances one cycle with what was applied.
    if (apply_at_once && have_latest) {
      applied_pos = latest_pos;
      applied_stiff = latest_stiff;
    }
    if (cycle > 0) {
      JointVector q_cmd, scale;
      for (int j = 0; j < kNumJoints; ++j) {
        const auto i = static_cast<std::size_t>(lola::kRightArmLolaIndex[j]);
        const double s = applied_stiff[i];
        scale[j] = std::max(s, kGearHoldStiffness);
        q_cmd[j] = s < kGearHoldStiffness ? sim->q[j] : static_cast<double>(applied_pos[i]);
      }
      nao::setSimTorqueScale(*model, *sim, scale);
      nao::stepSim(*model, *sim, q_cmd);
      for (int i = 0; i < kN; ++i) {
        const auto u = static_cast<std::size_t>(i);
        const double k = 25.0 * std::clamp<double>(applied_stiff[u], 0.0, 1.0);
        position[u] += static_cast<float>((applied_pos[u] - position[u]) * (1.0 - std::exp(-k * dt)));
      }
      for (int j = 0; j < kNumJoints; ++j)
        position[static_cast<std::size_t>(lola::kRightArmLolaIndex[j])] = static_cast<float>(sim->q[j]);
    }
    // What the client answered during the last cycle applies from now on (lola.md: from the
    // next cycle), so a sensor packet's answer first moves the body one cycle after it.
    if (have_latest) {
      applied_pos = latest_pos;
      applied_stiff = latest_stiff;
    }

    // 2. The sensor packet (or the injected fault instead of it).
    double v = 0;
    if (inj.close_at >= 0 && cycle >= inj.close_at) {
      ::close(client);
      client = -1;
      st.closed_by_injection = true;
      break;
    }
    sensor.position = position;
    if (inWindow(misreads, cycle, v)) sensor.position[21] += 0.5f;
    sensor.stiffness = applied_stiff;
    for (const Event& h : heats)
      if (cycle >= h.cycle) sensor.temperature[static_cast<std::size_t>(h.joint)] = 80.0f;
    std::size_t n = lola::writeSensorPacket(sensor, tx.data(), tx.size());
    bool send = true;
    if (inWindow(drops, cycle, v)) {
      send = false;
      ++st.dropped;
    } else if (atCycle(garbages, cycle, v)) {
      n = std::min<std::size_t>(static_cast<std::size_t>(std::max(1.0, v)), tx.size());
      for (std::size_t b = 0; b < n; ++b) tx[b] = static_cast<char>(rng() & 0xff);
      ++st.garbage;
    } else if (inWindow(bads, cycle, v)) {
      // The same map with Position one entry short: a whole, well-formed message of the wrong shape.
      std::string bytes(tx.data(), n);
      const std::string key("\xa8" "Position\xdc\x00\x19", 12);  // fixstr "Position", array16 of 25
      const auto at = bytes.find(key);
      if (at != std::string::npos) {
        bytes[at + 11] = 0x18;                    // 24 entries
        bytes.erase(at + 12 + 4 * 5, 5);          // drop one float32 (5 bytes)
      }
      n = bytes.size();
      std::memcpy(tx.data(), bytes.data(), n);
      ++st.bad_length;
    }
    if (atCycle(delays, cycle, v)) {
      ++st.delayed;
      sleepUntil(nao::monotonicNs() + static_cast<std::int64_t>(v * 1e6));
    }
    if (send) {
      const std::int64_t t_sent = nao::monotonicNs();
      std::size_t off = 0;
      while (off < n) {
        const ssize_t w = ::send(client, tx.data() + off, n - off, MSG_NOSIGNAL);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) break;
        off += static_cast<std::size_t>(w);
      }
      ++st.sent;
      sent_cycle_queue.push_back(cycle);
      sent_time_queue.push_back(t_sent);
    }
    ++st.cycles;
    next_deadline += lola::kCycleNs;

    // 3. Until the next deadline: read answers; the latest is applied from the next cycle.
    bool closed = false;
    for (;;) {
      const std::int64_t now = nao::monotonicNs();
      if (now >= next_deadline || g_quit != 0) break;
      pollfd pfd{client, POLLIN, 0};
      const int pr = ::poll(&pfd, 1, static_cast<int>(std::max<std::int64_t>(1, (next_deadline - now) / 1'000'000)));
      if (pr <= 0) continue;
      const ssize_t r = ::recv(client, rx.data() + rx_len, rx.size() - rx_len, MSG_DONTWAIT);
      if (r == 0 || (r < 0 && errno != EAGAIN && errno != EINTR)) {
        closed = true;
        break;
      }
      if (r < 0) continue;
      rx_len += static_cast<std::size_t>(r);
      for (;;) {
        const lola::ParseResult pr2 = reader.parse(rx.data(), rx_len);
        if (pr2.status == lola::ParseStatus::kIncomplete) {
          if (rx_len == rx.size()) rx_len = 0;
          break;
        }
        if (pr2.status == lola::ParseStatus::kBadSyntax) {
          ++st.malformed_received;
          rx_len = 0;
          break;
        }
        std::memmove(rx.data(), rx.data() + pr2.consumed, rx_len - pr2.consumed);
        rx_len -= pr2.consumed;
        if (pr2.status == lola::ParseStatus::kBadContent) {
          ++st.malformed_received;
          continue;
        }
        const std::int64_t t_rx = nao::monotonicNs();
        latest_pos = reader.actuator().position;
        latest_stiff = reader.actuator().stiffness;
        have_latest = true;
        if (sent_cycle_queue.empty()) {
          ++st.extra_answers;
          continue;
        }
        const std::int64_t answered_cycle = sent_cycle_queue.front();
        const double lat_us = static_cast<double>(t_rx - sent_time_queue.front()) * 1e-3;
        sent_cycle_queue.erase(sent_cycle_queue.begin());
        sent_time_queue.erase(sent_time_queue.begin());
        const bool in_cycle = answered_cycle == cycle && t_rx < next_deadline;
        ++st.answered;
        if (in_cycle) ++st.in_cycle;
        latencies_us.push_back(lat_us);
        rows.push_back(RxRow{answered_cycle, lat_us, in_cycle, reader.actuator()});
      }
    }
    if (closed) {
      ::close(client);
      client = -1;
      st.client_closed = true;
      // One client per run in our tests: serve the next one from the same body state.
    }
    ++cycle;
    if (client >= 0) sleepUntil(next_deadline);
  }
  if (client >= 0) ::close(client);
  ::close(server);
  ::unlink(socket_path.c_str());

  // Output.
  if (!log_path.empty()) {
    std::ofstream f(log_path);
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
  if (!summary_path.empty()) std::ofstream(summary_path) << js.str();
  std::cerr << "nao_lola_sim: " << st.cycles << " cycles, " << st.sent << " sent, " << st.answered << " answered ("
            << st.in_cycle << " within the cycle)\n";
  return 0;
}
