#include "nao/lola.hpp"

// msgpack-c without Boost: we use only its parser core and packer.
#ifndef MSGPACK_NO_BOOST
#define MSGPACK_NO_BOOST
#endif
#include <msgpack.hpp>

#include <algorithm>
#include <cstring>

namespace nao::lola {
namespace {

enum class FieldKind : std::uint8_t { kFloat, kBool, kString };

/// One key of a packet: where its array lives and how long it must be.
struct Field {
  const char* key = nullptr;
  FieldKind kind = FieldKind::kFloat;
  int length = 0;
  float* values = nullptr;                       ///< kFloat, kBool
  std::array<char, kRobotConfigChars>* strings = nullptr;  ///< kString
};

inline constexpr int kMaxFields = 13;
using FieldTable = std::array<Field, kMaxFields>;

template <std::size_t N>
Field floats(const char* key, std::array<float, N>& a, FieldKind kind = FieldKind::kFloat) {
  return Field{key, kind, static_cast<int>(N), a.data(), nullptr};
}

int sensorFields(SensorPacket& p, FieldTable& t) {
  int n = 0;
  t[n++] = floats("Position", p.position);
  t[n++] = floats("Stiffness", p.stiffness);
  t[n++] = floats("Temperature", p.temperature);
  t[n++] = floats("Current", p.current);
  t[n++] = floats("Status", p.status);
  t[n++] = floats("Accelerometer", p.accelerometer);
  t[n++] = floats("Gyroscope", p.gyroscope);
  t[n++] = floats("Angles", p.angles);
  t[n++] = floats("FSR", p.fsr);
  t[n++] = floats("Touch", p.touch);
  t[n++] = floats("Sonar", p.sonar);
  t[n++] = floats("Battery", p.battery);
  t[n++] = Field{"RobotConfig", FieldKind::kString, 4, nullptr, p.robot_config.data()};
  return n;
}

int actuatorFields(ActuatorPacket& p, FieldTable& t) {
  int n = 0;
  t[n++] = floats("Position", p.position);
  t[n++] = floats("Stiffness", p.stiffness);
  t[n++] = floats("Chest", p.chest);
  t[n++] = floats("LEar", p.l_ear);
  t[n++] = floats("REar", p.r_ear);
  t[n++] = floats("LEye", p.l_eye);
  t[n++] = floats("REye", p.r_eye);
  t[n++] = floats("LFoot", p.l_foot);
  t[n++] = floats("RFoot", p.r_foot);
  t[n++] = floats("Skull", p.skull);
  t[n++] = floats("Sonar", p.sonar, FieldKind::kBool);
  return n;
}

/// The SAX visitor: a map of string keys to flat arrays, written straight into the fields.
/// Never stops the parser for wrong content (so the message's end is still found); stops it
/// only for nesting deeper than a packet has (2), which keeps msgpack-c's stack in its reserve.
struct PacketVisitor : msgpack::null_visitor {
  FieldTable fields{};
  int n_fields = 0;
  std::array<int, kMaxFields> filled{};  ///< elements written per field
  std::array<bool, kMaxFields> seen{};
  int depth = 0;
  bool in_key = false;
  int current = -1;   ///< field of the value being read (-1: skipped key)
  int index = 0;      ///< element index within the current array
  bool bad = false;   ///< content is not this packet
  bool too_deep = false;

  void init() {
    filled.fill(0);
    seen.fill(false);
    depth = 0;
    in_key = false;
    current = -1;
    index = 0;
    bad = false;
    too_deep = false;
  }
  bool number(double v) {
    if (in_key || depth != 2) {  // a key that is not a string, or a scalar where an array belongs
      bad = true;
      return true;
    }
    if (current < 0) return true;
    Field& f = fields[static_cast<std::size_t>(current)];
    if (f.kind == FieldKind::kString || index >= f.length) {
      bad = true;
      return true;
    }
    f.values[index++] = static_cast<float>(v);
    filled[static_cast<std::size_t>(current)] = index;
    return true;
  }
  bool visit_nil() {
    bad = true;
    return true;
  }
  bool visit_boolean(bool v) { return number(v ? 1.0 : 0.0); }
  bool visit_positive_integer(std::uint64_t v) { return number(static_cast<double>(v)); }
  bool visit_negative_integer(std::int64_t v) { return number(static_cast<double>(v)); }
  bool visit_float32(float v) { return number(v); }
  bool visit_float64(double v) { return number(v); }
  bool visit_str(const char* s, std::uint32_t size) {
    if (in_key) {
      current = -1;
      for (int i = 0; i < n_fields; ++i) {
        const char* k = fields[static_cast<std::size_t>(i)].key;
        if (std::strlen(k) == size && std::memcmp(k, s, size) == 0) current = i;
      }
      if (current >= 0) {
        if (seen[static_cast<std::size_t>(current)]) bad = true;  // a key twice
        seen[static_cast<std::size_t>(current)] = true;
      }
      return true;
    }
    if (depth != 2) {
      bad = true;
      return true;
    }
    if (current < 0) return true;
    Field& f = fields[static_cast<std::size_t>(current)];
    if (f.kind != FieldKind::kString || index >= f.length) {
      bad = true;
      return true;
    }
    auto& dst = f.strings[index++];
    const std::size_t n = std::min<std::size_t>(size, kRobotConfigChars - 1);
    std::memcpy(dst.data(), s, n);
    dst[n] = '\0';
    filled[static_cast<std::size_t>(current)] = index;
    return true;
  }
  bool visit_bin(const char*, std::uint32_t) {
    bad = true;
    return true;
  }
  bool visit_ext(const char*, std::uint32_t) {
    bad = true;
    return true;
  }
  bool start_array(std::uint32_t n) {
    if (++depth > 2) {
      too_deep = true;
      return false;
    }
    if (depth != 2 || in_key) {
      bad = true;  // the top level must be a map, keys must be strings
      return true;
    }
    index = 0;
    if (current >= 0 && static_cast<int>(n) != fields[static_cast<std::size_t>(current)].length) bad = true;
    return true;
  }
  bool end_array() {
    --depth;
    return true;
  }
  bool start_map(std::uint32_t) {
    if (++depth > 2) {
      too_deep = true;
      return false;
    }
    if (depth != 1) bad = true;  // a map only at the top
    return true;
  }
  bool end_map() {
    --depth;
    return true;
  }
  bool start_map_key() {
    in_key = true;
    current = -1;
    return true;
  }
  bool end_map_key() {
    in_key = false;
    return true;
  }
  bool start_map_value() {
    index = 0;
    return true;
  }
  bool end_map_value() {
    // A scalar value where an array belongs leaves `filled` short: caught by the length check.
    current = -1;
    return true;
  }
};

/// msgpack-c's parse context bound to our visitor, kept for the reader's lifetime (see lola.hpp).
struct ParseContext : msgpack::detail::context<ParseContext> {
  explicit ParseContext(PacketVisitor& v) : v_(v) {}
  PacketVisitor& visitor() const { return v_; }
  PacketVisitor& v_;
};

/// A msgpack-c output stream over a fixed buffer.
struct FixedStream {
  char* buf;
  std::size_t cap;
  std::size_t len = 0;
  bool overflow = false;
  void write(const char* p, std::size_t n) {
    if (overflow || len + n > cap) {
      overflow = true;
      return;
    }
    std::memcpy(buf + len, p, n);
    len += n;
  }
};

/// Always a MessagePack float32: msgpack-c's pack_float writes whole numbers as integers
/// (0.0f becomes the integer 0), and LoLA's arrays are floats.
void writeFloat32(FixedStream& s, float v) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &v, sizeof bits);
  const char b[5] = {static_cast<char>(0xca), static_cast<char>(bits >> 24), static_cast<char>(bits >> 16),
                     static_cast<char>(bits >> 8), static_cast<char>(bits)};
  s.write(b, sizeof b);
}

std::size_t writeFields(const FieldTable& t, int n, char* buf, std::size_t cap) {
  FixedStream s{buf, cap};
  msgpack::packer<FixedStream> pk(s);
  pk.pack_map(static_cast<std::uint32_t>(n));
  for (int i = 0; i < n; ++i) {
    const Field& f = t[static_cast<std::size_t>(i)];
    const std::size_t klen = std::strlen(f.key);
    pk.pack_str(static_cast<std::uint32_t>(klen));
    pk.pack_str_body(f.key, static_cast<std::uint32_t>(klen));
    pk.pack_array(static_cast<std::uint32_t>(f.length));
    for (int e = 0; e < f.length; ++e) {
      switch (f.kind) {
        case FieldKind::kFloat:
          writeFloat32(s, f.values[e]);
          break;
        case FieldKind::kBool:
          if (f.values[e] != 0.0f)
            pk.pack_true();
          else
            pk.pack_false();
          break;
        case FieldKind::kString: {
          const char* str = f.strings[e].data();
          const std::size_t slen = strnlen(str, kRobotConfigChars);
          pk.pack_str(static_cast<std::uint32_t>(slen));
          pk.pack_str_body(str, static_cast<std::uint32_t>(slen));
          break;
        }
      }
    }
  }
  return s.overflow ? 0 : s.len;
}

}  // namespace

struct LolaReader::Impl {
  explicit Impl(PacketKind k) : kind(k), context(visitor) {
    visitor.n_fields = kind == PacketKind::kSensor ? sensorFields(sensor, visitor.fields)
                                                   : actuatorFields(actuator, visitor.fields);
  }
  PacketKind kind;
  SensorPacket sensor;
  ActuatorPacket actuator;
  PacketVisitor visitor;
  ParseContext context;
};

LolaReader::LolaReader(PacketKind kind) : impl_(std::make_unique<Impl>(kind)) {}
LolaReader::~LolaReader() = default;

ParseResult LolaReader::parse(const char* data, std::size_t len) {
  ParseResult r;
  if (len == 0) return r;
  Impl& m = *impl_;
  m.context.init();  // also calls visitor.init()
  std::size_t off = 0;
  const msgpack::parse_return ret = m.context.execute(data, len, off);
  switch (ret) {
    case msgpack::PARSE_CONTINUE:
      r.status = ParseStatus::kIncomplete;
      return r;
    case msgpack::PARSE_SUCCESS:
    case msgpack::PARSE_EXTRA_BYTES:
      break;
    default:  // PARSE_PARSE_ERROR, PARSE_STOP_VISITOR (too deep)
      r.status = ParseStatus::kBadSyntax;
      return r;
  }
  r.consumed = off;
  const PacketVisitor& v = m.visitor;
  bool ok = !v.bad;
  for (int i = 0; ok && i < v.n_fields; ++i)
    ok = v.seen[static_cast<std::size_t>(i)] && v.filled[static_cast<std::size_t>(i)] == v.fields[static_cast<std::size_t>(i)].length;
  r.status = ok ? ParseStatus::kComplete : ParseStatus::kBadContent;
  return r;
}

const SensorPacket& LolaReader::sensor() const { return impl_->sensor; }
const ActuatorPacket& LolaReader::actuator() const { return impl_->actuator; }

std::size_t writeSensorPacket(const SensorPacket& p, char* buf, std::size_t cap) {
  FieldTable t{};
  // The table points into the packet for writing only; the cast keeps one table builder.
  const int n = sensorFields(const_cast<SensorPacket&>(p), t);
  return writeFields(t, n, buf, cap);
}

std::size_t writeActuatorPacket(const ActuatorPacket& p, char* buf, std::size_t cap) {
  FieldTable t{};
  const int n = actuatorFields(const_cast<ActuatorPacket&>(p), t);
  return writeFields(t, n, buf, cap);
}

}  // namespace nao::lola
