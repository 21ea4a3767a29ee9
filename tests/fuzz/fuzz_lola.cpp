// Fuzz target: LoLA packets (nao::lola::LolaReader, what nao_rt --robot lola reads from the
// robot and nao_lola_sim from nao_rt). The first byte picks the packet kind (even: sensor, odd:
// actuator); the rest is a byte stream read the way the backend reads its socket buffer: parse,
// skip `consumed` bytes of a whole message (complete or of the wrong content), stop when the
// bytes end inside a message or are not MessagePack.
// Checks: consumed is within the bytes and never 0 for a whole message; a complete packet
// written back and read again is complete, the same length, and the same packet bit for bit.
#include "fuzz_util.hpp"

#include "nao/lola.hpp"

#include <array>
#include <cstring>

namespace {

using nao::lola::LolaReader;
using nao::lola::PacketKind;
using nao::lola::ParseStatus;

template <class Packet>
bool sameBits(const Packet& a, const Packet& b) {
  return std::memcmp(&a, &b, sizeof(Packet)) == 0;
}

/// A complete packet survives writing and reading again unchanged.
void roundTrip(const LolaReader& got, PacketKind kind, LolaReader& again) {
  std::array<char, nao::lola::kMaxPacketBytes> buf{};
  const std::size_t n = kind == PacketKind::kSensor ? nao::lola::writeSensorPacket(got.sensor(), buf.data(), buf.size())
                                                    : nao::lola::writeActuatorPacket(got.actuator(), buf.data(), buf.size());
  NAO_FUZZ_CHECK(n > 0);
  const nao::lola::ParseResult r = again.parse(buf.data(), n);
  NAO_FUZZ_CHECK(r.status == ParseStatus::kComplete && r.consumed == n);
  if (kind == PacketKind::kSensor) {
    // RobotConfig: the strings up to their NUL (what follows it in the array is not data).
    nao::lola::SensorPacket want = got.sensor(), have = again.sensor();
    for (nao::lola::SensorPacket* s : {&want, &have})
      for (auto& c : s->robot_config) {
        const std::size_t len = strnlen(c.data(), c.size());
        std::memset(c.data() + len, 0, c.size() - len);
      }
    NAO_FUZZ_CHECK(sameBits(have, want));
  } else {
    // The actuator's Sonar goes out as booleans: only non-zero-ness survives.
    nao::lola::ActuatorPacket want = got.actuator();
    for (float& s : want.sonar) s = s != 0.0f ? 1.0f : 0.0f;
    nao::lola::ActuatorPacket have = again.actuator();
    for (float& s : have.sonar) s = s != 0.0f ? 1.0f : 0.0f;
    NAO_FUZZ_CHECK(sameBits(have, want));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Built once, as the backend builds its readers at configure time.
  static LolaReader sensor(PacketKind::kSensor), actuator(PacketKind::kActuator);
  static LolaReader sensor_again(PacketKind::kSensor), actuator_again(PacketKind::kActuator);
  if (size == 0) return 0;
  const PacketKind kind = (data[0] & 1) == 0 ? PacketKind::kSensor : PacketKind::kActuator;
  LolaReader& reader = kind == PacketKind::kSensor ? sensor : actuator;
  LolaReader& again = kind == PacketKind::kSensor ? sensor_again : actuator_again;
  const char* p = reinterpret_cast<const char*>(data + 1);
  std::size_t left = size - 1;
  while (left > 0) {
    const nao::lola::ParseResult r = reader.parse(p, left);
    if (r.status == ParseStatus::kIncomplete || r.status == ParseStatus::kBadSyntax) break;
    NAO_FUZZ_CHECK(r.consumed > 0 && r.consumed <= left);
    if (r.status == ParseStatus::kComplete) roundTrip(reader, kind, again);
    p += r.consumed;
    left -= r.consumed;
  }
  return 0;
}
