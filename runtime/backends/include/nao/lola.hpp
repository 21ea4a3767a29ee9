// LoLA, the NAO V6's low-level robot interface (docs/lola.md): the 25-joint order, the two
// packets as fixed-size structs, and their MessagePack reader and writers.
//
// The reader is msgpack-c's visitor (SAX) parser driven into fixed buffers: no msgpack::object,
// no zone, no heap. msgpack-c's free function msgpack::parse builds a new parse context per call,
// whose stack reserves heap memory; LolaReader keeps one context for its lifetime (reserved at
// construction, configure time) and re-initialises it per message, and refuses nesting deeper
// than a packet has, so that stack never grows. Real-time safe after construction.
#pragma once

#include "nao/arm_model.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>

namespace nao::lola {

/// LoLA joints: Position, Stiffness, Temperature, Current, Status arrays are in this order.
inline constexpr int kNumLolaJoints = 25;
inline constexpr std::array<const char*, kNumLolaJoints> kLolaJointNames = {
    "HeadYaw",        "HeadPitch",     "LShoulderPitch", "LShoulderRoll", "LElbowYaw",
    "LElbowRoll",     "LWristYaw",     "LHipYawPitch",   "LHipRoll",      "LHipPitch",
    "LKneePitch",     "LAnklePitch",   "LAnkleRoll",     "RHipRoll",      "RHipPitch",
    "RKneePitch",     "RAnklePitch",   "RAnkleRoll",     "RShoulderPitch", "RShoulderRoll",
    "RElbowYaw",      "RElbowRoll",    "RWristYaw",      "LHand",         "RHand"};
/// LoLA index of each of our arm joints (kJointNames order: RShoulderPitch ... RWristYaw).
inline constexpr std::array<int, kNumJoints> kRightArmLolaIndex = {18, 19, 20, 21, 22};
/// One LoLA cycle: the robot sends a sensor packet every 12 ms.
inline constexpr std::int64_t kCycleNs = 12'000'000;
/// Bytes a packet of ours never exceeds (a full sensor packet is < 1 KiB).
inline constexpr std::size_t kMaxPacketBytes = 4096;
inline constexpr std::size_t kRobotConfigChars = 32;

/// Robot -> client, every cycle (lola.md "Sensor packet").
struct SensorPacket {
  std::array<float, kNumLolaJoints> position{}, stiffness{}, temperature{}, current{}, status{};
  std::array<float, 3> accelerometer{}, gyroscope{};
  std::array<float, 2> angles{};
  std::array<float, 8> fsr{};
  std::array<float, 14> touch{};
  std::array<float, 2> sonar{};
  std::array<float, 4> battery{};
  std::array<std::array<char, kRobotConfigChars>, 4> robot_config{};  ///< NUL-terminated, truncated
};

/// Client -> robot, once per sensor packet (lola.md "Actuator packet").
struct ActuatorPacket {
  std::array<float, kNumLolaJoints> position{}, stiffness{};
  std::array<float, 3> chest{};
  std::array<float, 10> l_ear{}, r_ear{};
  std::array<float, 24> l_eye{}, r_eye{};
  std::array<float, 3> l_foot{}, r_foot{};
  std::array<float, 12> skull{};
  std::array<float, 2> sonar{};  ///< sent as booleans (non-zero: on)
};

enum class ParseStatus {
  kComplete,    ///< one whole message with every key at its length: the packet is filled
  kIncomplete,  ///< the bytes end inside a message: read more
  kBadContent,  ///< a whole MessagePack message, but not this packet (keys, lengths, types): skip `consumed` bytes
  kBadSyntax,   ///< not MessagePack (or nested deeper than a packet): the message's end is unknown
};

struct ParseResult {
  ParseStatus status = ParseStatus::kIncomplete;
  std::size_t consumed = 0;  ///< bytes of the message (kComplete, kBadContent)
};

enum class PacketKind { kSensor, kActuator };

/// Reads one packet kind from MessagePack bytes into a fixed struct. Keys other than the
/// packet's are skipped; every key of the packet must be present with its exact length.
class LolaReader {
 public:
  /// Configure time (allocates the parse context once).
  explicit LolaReader(PacketKind kind);
  ~LolaReader();
  LolaReader(const LolaReader&) = delete;
  LolaReader& operator=(const LolaReader&) = delete;

  /// Parses the message at the start of data[0, len). On kComplete the packet below holds it;
  /// otherwise the packet keeps what the last complete message left (partly overwritten on
  /// kBadContent). Real-time safe: no allocation, no exception.
  ParseResult parse(const char* data, std::size_t len);

  const SensorPacket& sensor() const;
  const ActuatorPacket& actuator() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Writes a packet as a MessagePack map (values float32; the actuator's Sonar as booleans,
/// RobotConfig as strings) into buf[0, cap). Returns the bytes written, 0 if cap is too small.
/// Real-time safe.
std::size_t writeSensorPacket(const SensorPacket& p, char* buf, std::size_t cap);
std::size_t writeActuatorPacket(const ActuatorPacket& p, char* buf, std::size_t cap);

}  // namespace nao::lola
