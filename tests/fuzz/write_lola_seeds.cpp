// nao_fuzz_lola_seeds DIR: writes the seed corpus of fuzz_lola with the project's own packet
// writers (first byte: 0 sensor, 1 actuator): a sensor and an actuator packet, two packets back
// to back, a truncated one, a whole message of the wrong kind and one with a byte MessagePack
// never uses.
#include "nao/lola.hpp"

#include <cstdio>
#include <filesystem>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
using namespace nao::lola;
static void put(const std::string& path, char kind, const char* b, std::size_t n) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    std::perror(path.c_str());
    std::exit(1);
  }
  std::fputc(kind, f);
  std::fwrite(b, 1, n, f);
  std::fclose(f);
}
int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  const std::string dir = argv[1];
  std::filesystem::create_directories(dir);
  SensorPacket s;
  for (int i = 0; i < kNumLolaJoints; ++i) {
    const auto f = static_cast<float>(i);
    s.position[i] = 0.01f * f;
    s.stiffness[i] = 1.0f;
    s.temperature[i] = 35.0f + f;
    s.current[i] = 0.1f;
  }
  s.battery = {0.9f, 3.0f, 25.0f, 0.0f};
  std::strcpy(s.robot_config[0].data(), "P0000074A04S8C700011");
  std::strcpy(s.robot_config[1].data(), "6.0.0");
  std::strcpy(s.robot_config[2].data(), "P0000073A04S8C700017");
  std::strcpy(s.robot_config[3].data(), "6.0.0");
  ActuatorPacket a;
  for (int i = 0; i < kNumLolaJoints; ++i) {
    a.position[i] = -0.02f * static_cast<float>(i);
    a.stiffness[i] = 0.5f;
  }
  a.sonar = {1.0f, 0.0f};
  char bs[kMaxPacketBytes], ba[kMaxPacketBytes];
  const std::size_t ns = writeSensorPacket(s, bs, sizeof bs), na = writeActuatorPacket(a, ba, sizeof ba);
  put(dir + "/sensor.msgpack", 0, bs, ns);
  put(dir + "/actuator.msgpack", 1, ba, na);
  std::string two(bs, ns); two.append(bs, ns);
  put(dir + "/sensor_twice.msgpack", 0, two.data(), two.size());
  put(dir + "/sensor_truncated.msgpack", 0, bs, ns / 2);
  put(dir + "/actuator_as_sensor.msgpack", 0, ba, na);     // whole message, wrong keys
  std::string bad(bs, ns); bad[ns / 3] = static_cast<char>(0xc1);  // never-used MessagePack byte
  put(dir + "/sensor_bad_byte.msgpack", 0, bad.data(), bad.size());
  std::printf("sensor %zu bytes, actuator %zu bytes\n", ns, na);
}
