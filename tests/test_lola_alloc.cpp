// Real-time property: after construction, reading and writing LoLA packets allocates nothing,
// whatever comes in (good packets, bad content, garbage, deep nesting).
#include "nao/lola.hpp"
#include "support/alloc_counter.hpp"

#include <doctest/doctest.h>

#include <random>
#include <string>
#include <vector>

using namespace nao::lola;
using nao::test::CountAllocations;

TEST_CASE("LolaReader::parse and the packet writers allocate nothing after construction") {
  LolaReader sensor_reader(PacketKind::kSensor);
  LolaReader actuator_reader(PacketKind::kActuator);
  SensorPacket s;
  s.position.fill(0.25f);
  ActuatorPacket a;
  a.stiffness.fill(0.5f);
  std::vector<char> sbuf(kMaxPacketBytes), abuf(kMaxPacketBytes), junk(2048);
  std::string deep(64, static_cast<char>(0x91));
  std::mt19937 rng(3);
  for (char& c : junk) c = static_cast<char>(rng() & 0xff);

  CountAllocations count;
  std::int64_t complete = 0;
  for (int i = 0; i < 1000; ++i) {
    const std::size_t ns = writeSensorPacket(s, sbuf.data(), sbuf.size());
    const std::size_t na = writeActuatorPacket(a, abuf.data(), abuf.size());
    complete += sensor_reader.parse(sbuf.data(), ns).status == ParseStatus::kComplete;
    complete += actuator_reader.parse(abuf.data(), na).status == ParseStatus::kComplete;
    sensor_reader.parse(abuf.data(), na);             // the wrong packet: bad content
    sensor_reader.parse(sbuf.data(), ns / 2);         // incomplete
    sensor_reader.parse(junk.data(), junk.size());    // garbage
    sensor_reader.parse(deep.data(), deep.size());    // too deep
  }
  const std::int64_t n = count.count();
  CHECK(complete == 2000);
  CHECK_MESSAGE(n == 0, "allocations while reading and writing 1000 x 6 packets: " << n);
}
