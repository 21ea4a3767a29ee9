// LoLA packets (lola.hpp): what we write reads back exactly, every key and length of lola.md is
// required, and no input — truncated, malformed, random, too deeply nested — crashes the reader
// or is taken for a packet.
#define MSGPACK_NO_BOOST
#include "nao/lola.hpp"

#include <doctest/doctest.h>
#include <msgpack.hpp>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

using namespace nao::lola;

namespace {

SensorPacket sampleSensor() {
  SensorPacket p;
  for (int i = 0; i < kNumLolaJoints; ++i) {
    const auto u = static_cast<std::size_t>(i);
    p.position[u] = 0.01f * static_cast<float>(i) - 0.1f;
    p.stiffness[u] = 0.04f * static_cast<float>(i);
    p.temperature[u] = 30.0f + static_cast<float>(i);
    p.current[u] = 0.001f * static_cast<float>(i);
    p.status[u] = static_cast<float>(i % 3);
  }
  p.accelerometer = {0.1f, -0.2f, -9.81f};
  p.gyroscope = {0.01f, 0.02f, 0.03f};
  p.angles = {0.001f, -0.002f};
  p.fsr = {1, 2, 3, 4, 5, 6, 7, 8};
  p.touch[3] = 1.0f;
  p.sonar = {0.5f, 2.55f};
  p.battery = {0.9f, -1.2f, 128.0f, 33.0f};
  std::strcpy(p.robot_config[0].data(), "P0000074A05S94700017");
  std::strcpy(p.robot_config[1].data(), "6.0.0");
  std::strcpy(p.robot_config[2].data(), "P0000073A03S94600016");
  std::strcpy(p.robot_config[3].data(), "6.0.0");
  return p;
}

std::string bytesOf(const SensorPacket& p) {
  std::vector<char> buf(kMaxPacketBytes);
  const std::size_t n = writeSensorPacket(p, buf.data(), buf.size());
  REQUIRE(n > 0);
  return std::string(buf.data(), n);
}

/// A sensor packet written by msgpack-c's own map packer from (key, length) pairs, values
/// float64 or integers as a python client would send them.
std::string packedMap(const std::vector<std::pair<std::string, int>>& keys, bool integers = false) {
  msgpack::sbuffer sb;
  msgpack::packer<msgpack::sbuffer> pk(sb);
  pk.pack_map(static_cast<std::uint32_t>(keys.size()));
  for (const auto& [k, n] : keys) {
    pk.pack(k);
    pk.pack_array(static_cast<std::uint32_t>(n));
    for (int i = 0; i < n; ++i) {
      if (k == "RobotConfig")
        pk.pack(std::string("x"));
      else if (integers)
        pk.pack(i);
      else
        pk.pack_double(0.5 + i);
    }
  }
  return std::string(sb.data(), sb.size());
}

const std::vector<std::pair<std::string, int>> kSensorKeys = {
    {"Position", 25}, {"Stiffness", 25}, {"Temperature", 25}, {"Current", 25}, {"Status", 25},
    {"Accelerometer", 3}, {"Gyroscope", 3}, {"Angles", 2}, {"FSR", 8}, {"Touch", 14}, {"Sonar", 2},
    {"Battery", 4}, {"RobotConfig", 4}};

}  // namespace

TEST_CASE("a sensor packet written by writeSensorPacket reads back bit for bit") {
  const SensorPacket p = sampleSensor();
  const std::string b = bytesOf(p);
  LolaReader r(PacketKind::kSensor);
  const ParseResult res = r.parse(b.data(), b.size());
  REQUIRE(res.status == ParseStatus::kComplete);
  CHECK(res.consumed == b.size());
  const SensorPacket& q = r.sensor();
  CHECK(std::memcmp(q.position.data(), p.position.data(), sizeof p.position) == 0);
  CHECK(std::memcmp(q.temperature.data(), p.temperature.data(), sizeof p.temperature) == 0);
  CHECK(std::memcmp(q.battery.data(), p.battery.data(), sizeof p.battery) == 0);
  CHECK(std::string(q.robot_config[0].data()) == "P0000074A05S94700017");
  CHECK(std::string(q.robot_config[3].data()) == "6.0.0");
}

TEST_CASE("an actuator packet reads back, Sonar as booleans and every value a float32") {
  ActuatorPacket a;
  for (int i = 0; i < kNumLolaJoints; ++i) a.position[static_cast<std::size_t>(i)] = static_cast<float>(i);  // whole numbers
  a.stiffness.fill(0.0f);
  a.sonar = {1.0f, 0.0f};
  std::vector<char> buf(kMaxPacketBytes);
  const std::size_t n = writeActuatorPacket(a, buf.data(), buf.size());
  REQUIRE(n > 0);
  // Whole numbers stay float32 (0xca), never MessagePack integers.
  const msgpack::object_handle oh = msgpack::unpack(buf.data(), n);
  const msgpack::object& m = oh.get();
  REQUIRE(m.type == msgpack::type::MAP);
  CHECK(m.via.map.size == 11);
  for (std::uint32_t i = 0; i < m.via.map.size; ++i) {
    const auto& kv = m.via.map.ptr[i];
    const std::string key = kv.key.as<std::string>();
    for (std::uint32_t e = 0; e < kv.val.via.array.size; ++e)
      CHECK_MESSAGE(kv.val.via.array.ptr[e].type == (key == "Sonar" ? msgpack::type::BOOLEAN : msgpack::type::FLOAT32),
                    key << "[" << e << "]");
  }
  LolaReader r(PacketKind::kActuator);
  REQUIRE(r.parse(buf.data(), n).status == ParseStatus::kComplete);
  CHECK(r.actuator().position[24] == 24.0f);
  CHECK(r.actuator().sonar[0] == 1.0f);
  CHECK(r.actuator().sonar[1] == 0.0f);
}

TEST_CASE("float64 and integer values are accepted; unknown keys are skipped") {
  LolaReader r(PacketKind::kSensor);
  std::string b = packedMap(kSensorKeys);
  REQUIRE(r.parse(b.data(), b.size()).status == ParseStatus::kComplete);
  CHECK(r.sensor().position[24] == 24.5f);
  b = packedMap(kSensorKeys, true);
  REQUIRE(r.parse(b.data(), b.size()).status == ParseStatus::kComplete);
  CHECK(r.sensor().temperature[7] == 7.0f);
  auto keys = kSensorKeys;
  keys.insert(keys.begin() + 3, {"FutureKey", 5});
  b = packedMap(keys);
  CHECK(r.parse(b.data(), b.size()).status == ParseStatus::kComplete);
}

TEST_CASE("a missing key, a wrong length or a wrong type is bad content, skipped whole") {
  LolaReader r(PacketKind::kSensor);
  for (std::size_t drop = 0; drop < kSensorKeys.size(); ++drop) {
    auto keys = kSensorKeys;
    keys.erase(keys.begin() + static_cast<std::ptrdiff_t>(drop));
    const std::string b = packedMap(keys);
    const ParseResult res = r.parse(b.data(), b.size());
    CHECK_MESSAGE(res.status == ParseStatus::kBadContent, "without " << kSensorKeys[drop].first);
    CHECK(res.consumed == b.size());
  }
  for (std::size_t k = 0; k < kSensorKeys.size(); ++k)
    for (int delta : {-1, +1}) {
      auto keys = kSensorKeys;
      keys[k].second += delta;
      const std::string b = packedMap(keys);
      CHECK_MESSAGE(r.parse(b.data(), b.size()).status == ParseStatus::kBadContent,
                    kSensorKeys[k].first << " of length " << keys[k].second);
    }
  {  // a scalar where an array belongs, a string among the positions, an array at the top
    msgpack::sbuffer sb;
    msgpack::packer<msgpack::sbuffer> pk(sb);
    pk.pack_array(2);
    pk.pack(1);
    pk.pack(2);
    CHECK(r.parse(sb.data(), sb.size()).status == ParseStatus::kBadContent);
  }
  auto keys = kSensorKeys;  // a key twice is not one packet
  keys.push_back({"Position", 25});
  const std::string b = packedMap(keys);
  CHECK(r.parse(b.data(), b.size()).status == ParseStatus::kBadContent);
}

TEST_CASE("two packets back to back parse one at a time; every prefix is incomplete") {
  const std::string one = bytesOf(sampleSensor());
  const std::string two = one + one;
  LolaReader r(PacketKind::kSensor);
  ParseResult res = r.parse(two.data(), two.size());
  REQUIRE(res.status == ParseStatus::kComplete);
  CHECK(res.consumed == one.size());
  for (std::size_t n = 1; n < one.size(); ++n) {
    res = r.parse(one.data(), n);
    REQUIRE_MESSAGE(res.status == ParseStatus::kIncomplete, "prefix of " << n << " bytes");
  }
}

TEST_CASE("nesting deeper than a packet is refused as bad syntax") {
  std::string deep;
  for (int i = 0; i < 100; ++i) deep += static_cast<char>(0x91);  // fixarray of 1, 100 deep
  deep += static_cast<char>(0x01);
  LolaReader r(PacketKind::kSensor);
  CHECK(r.parse(deep.data(), deep.size()).status == ParseStatus::kBadSyntax);
  const char reserved[] = {static_cast<char>(0xc1)};  // never used in MessagePack
  CHECK(r.parse(reserved, 1).status == ParseStatus::kBadSyntax);
}

TEST_CASE("random bytes and corrupted packets never crash the reader and are never a packet") {
  std::mt19937 rng(15);
  LolaReader r(PacketKind::kSensor);
  const std::string good = bytesOf(sampleSensor());
  int complete = 0;
  for (int it = 0; it < 20000; ++it) {
    std::string b;
    if (it % 2 == 0) {
      b.resize(1 + rng() % 1200);
      for (char& c : b) c = static_cast<char>(rng() & 0xff);
    } else {  // flip a few bytes of a good packet
      b = good;
      for (int k = 0; k < 1 + static_cast<int>(rng() % 4); ++k) b[rng() % b.size()] = static_cast<char>(rng() & 0xff);
    }
    const ParseResult res = r.parse(b.data(), b.size());
    CHECK(res.consumed <= b.size());
    if (res.status == ParseStatus::kComplete && it % 2 == 0) ++complete;
  }
  CHECK(complete == 0);
}
