#include "nao/model_file.hpp"
#include "nao/file_io.hpp"
#include "nao/text_guard.hpp"

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

// ModelFile::data() hands out the stored little-endian floats in place (the runtime's
// Eigen::Map views and the compiled-in blob rely on it): that is only right on a
// little-endian host. Everything else in this file encodes and decodes byte by byte.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "model.bin views need a little-endian host");

namespace nao {
namespace {

// Layout of model.bin (docs/policy.md).
constexpr std::size_t kFixedBytes = 72;       // magic, version, header size, 14 u32 fields
constexpr std::size_t kNameBytes = 32;        // joint and movement names
constexpr std::size_t kJointBytes = kNameBytes + 3 * 8;
constexpr std::size_t kTensorNameBytes = 64;
constexpr std::size_t kEntryBytes = kTensorNameBytes + 4 + 4 * 4 + 8 + 8;
constexpr std::size_t kChecksumBytes = 8;
constexpr int kMaxRank = 4;

// Caps on the counts read before the architecture is checked: a corrupt or hostile header
// must not make the reader allocate or loop without bound.
constexpr std::uint32_t kMaxFfnCount = 64;
constexpr std::uint32_t kMaxTokens = 64;
constexpr std::uint32_t kMaxMovements = 4096;
constexpr std::uint32_t kMaxTensors = 1u << 20;
constexpr std::uint64_t kMaxFileBytes = std::uint64_t{1} << 36;  // 64 GiB: far above any policy

constexpr double kJointTolerance = 1e-9;

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw ModelFileError(origin + ": " + what);
}

std::string hex64(std::uint64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string number(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.15g", v);
  return buf;
}

std::size_t alignUp(std::size_t n) { return (n + kModelAlignment - 1) / kModelAlignment * kModelAlignment; }

// ---- little-endian encoding ----------------------------------------------------------------

void storeU32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

void storeU64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

void storeF64(std::uint8_t* p, double v) {
  std::uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  storeU64(p, bits);
}

void storeF32(std::uint8_t* p, float v) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  storeU32(p, bits);
}

std::uint32_t loadU32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= std::uint32_t{p[i]} << (8 * i);
  return v;
}

std::uint64_t loadU64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= std::uint64_t{p[i]} << (8 * i);
  return v;
}

double loadF64(const std::uint8_t* p) {
  const std::uint64_t bits = loadU64(p);
  double v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}

float loadF32(const std::uint8_t* p) {
  const std::uint32_t bits = loadU32(p);
  float v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}

/// Appends fixed-width little-endian fields to a presized buffer.
class Writer {
 public:
  explicit Writer(std::vector<std::uint8_t>& out) : out_(out) {}
  void u32(std::uint32_t v) { storeU32(take(4), v); }
  void u64(std::uint64_t v) { storeU64(take(8), v); }
  void f64(double v) { storeF64(take(8), v); }
  /// NUL-padded to `width`; the caller has checked that `s` fits with its terminator.
  void name(const std::string& s, std::size_t width) {
    std::uint8_t* p = take(width);
    std::memcpy(p, s.data(), s.size());
  }
  void raw(const std::string& s) {
    if (!s.empty()) std::memcpy(take(s.size()), s.data(), s.size());
  }
  std::size_t pos() const { return pos_; }

 private:
  std::uint8_t* take(std::size_t n) {
    assert(pos_ + n <= out_.size());
    std::uint8_t* p = out_.data() + pos_;
    pos_ += n;
    return p;
  }
  std::vector<std::uint8_t>& out_;
  std::size_t pos_ = 0;
};

// ---- the header, as stored ------------------------------------------------------------------

struct RawEntry {
  std::string name;
  std::uint32_t rank = 0;
  std::uint32_t dims[kMaxRank] = {0, 0, 0, 0};
  std::uint64_t offset = 0;
  std::uint64_t count = 0;
};

enum Field : int {
  kDModel, kHeads, kEncLayers, kDecLayers, kFfnCount, kTokens, kFeatures, kMovements, kClusters, kMaxSteps, kWindow,
  kChunk, kBins, kConditioning, kNumFields
};
constexpr const char* kFieldNames[kNumFields] = {"d_model", "heads", "encoder_layers", "decoder_layers", "ffn count",
                                                 "tokens", "features", "movements", "clusters", "max_steps", "window",
                                                 "chunk", "bins", "conditioning"};

struct RawHeader {
  std::uint32_t header_size = 0;
  std::uint32_t fields[kNumFields] = {};
  std::vector<std::uint32_t> ffn;
  std::vector<TrainedJoint> joints;
  std::vector<std::string> movements;
  std::string metadata;
  std::vector<RawEntry> table;
};

enum class Walk { kOk, kShort, kBad };

/// Reads the header fields at `bytes[0, limit)`. Every read is bounded by `limit`: a read that
/// would cross it stops the walk with kShort if the file simply ends there (`limit` is the
/// file size, below the stored header size) and kBad if it crosses the stored header size
/// (the header contradicts itself). Counts are capped before anything is sized by them.
class HeaderWalk {
 public:
  HeaderWalk(const std::uint8_t* bytes, std::size_t limit, bool limit_is_file_end)
      : p_(bytes), limit_(limit), short_is_truncation_(limit_is_file_end) {}

  Walk run(RawHeader& h) {
    pos_ = 12;
    if (!need(4)) return status_;
    h.header_size = loadU32(p_ + 12);
    pos_ = 16;
    for (std::uint32_t& f : h.fields) {
      if (!need(4)) return status_;
      f = loadU32(p_ + pos_);
      pos_ += 4;
    }
    if (h.fields[kFfnCount] > kMaxFfnCount) return bad("ffn count " + std::to_string(h.fields[kFfnCount]) + " is absurd");
    if (h.fields[kTokens] > kMaxTokens) return bad("tokens " + std::to_string(h.fields[kTokens]) + " is absurd");
    if (h.fields[kMovements] > kMaxMovements)
      return bad("movements " + std::to_string(h.fields[kMovements]) + " is absurd");

    h.ffn.resize(h.fields[kFfnCount]);
    for (std::uint32_t& w : h.ffn) {
      if (!need(4)) return status_;
      w = loadU32(p_ + pos_);
      pos_ += 4;
    }
    h.joints.resize(h.fields[kTokens]);
    for (std::size_t j = 0; j < h.joints.size(); ++j) {
      TrainedJoint& jt = h.joints[j];
      if (!need(kJointBytes)) return status_;
      if (!name(kNameBytes, jt.name)) return bad("joint " + std::to_string(j) + " name is not NUL-terminated");
      jt.lower = loadF64(p_ + pos_);
      jt.upper = loadF64(p_ + pos_ + 8);
      jt.velocity = loadF64(p_ + pos_ + 16);
      pos_ += 24;
    }
    h.movements.resize(h.fields[kMovements]);
    for (std::size_t m = 0; m < h.movements.size(); ++m) {
      if (!need(kNameBytes)) return status_;
      if (!name(kNameBytes, h.movements[m])) return bad("movement " + std::to_string(m) + " name is not NUL-terminated");
    }
    if (!need(4)) return status_;
    const std::uint32_t meta_len = loadU32(p_ + pos_);
    pos_ += 4;
    if (!need(meta_len)) return status_;
    h.metadata.assign(reinterpret_cast<const char*>(p_ + pos_), meta_len);
    pos_ += meta_len;

    if (!need(4)) return status_;
    const std::uint32_t count = loadU32(p_ + pos_);
    pos_ += 4;
    if (count > kMaxTensors) return bad("tensor count " + std::to_string(count) + " is absurd");
    if (!need(std::size_t{count} * kEntryBytes)) return status_;
    h.table.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      RawEntry& e = h.table[i];
      if (!name(kTensorNameBytes, e.name)) return bad("tensor " + std::to_string(i) + " name is not NUL-terminated");
      e.rank = loadU32(p_ + pos_);
      for (int k = 0; k < kMaxRank; ++k) e.dims[k] = loadU32(p_ + pos_ + 4 + 4 * k);
      e.offset = loadU64(p_ + pos_ + 20);
      e.count = loadU64(p_ + pos_ + 28);
      pos_ += 36;
    }
    if (pos_ != h.header_size)
      return bad("header size field says " + std::to_string(h.header_size) + " bytes, the header ends at byte " +
                 std::to_string(pos_));
    return Walk::kOk;
  }

  const std::string& problem() const { return problem_; }

 private:
  bool need(std::size_t n) {
    if (n <= limit_ && pos_ <= limit_ - n) return true;
    if (short_is_truncation_) {
      status_ = Walk::kShort;
    } else {
      status_ = Walk::kBad;
      problem_ = "the header runs past its stated size (" + std::to_string(limit_) + " bytes)";
    }
    return false;
  }
  Walk bad(std::string what) {
    problem_ = std::move(what);
    return Walk::kBad;
  }
  /// A NUL-padded name of `width` bytes at pos_ (already inside the limit).
  bool name(std::size_t width, std::string& out) {
    const auto* begin = reinterpret_cast<const char*>(p_ + pos_);
    const auto* nul = static_cast<const char*>(std::memchr(begin, 0, width));
    if (nul == nullptr) return false;
    out.assign(begin, nul);
    pos_ += width;
    return true;
  }

  const std::uint8_t* p_;
  std::size_t limit_;
  bool short_is_truncation_;
  std::size_t pos_ = 0;
  Walk status_ = Walk::kOk;
  std::string problem_;
};

/// Element count of a stored shape; 0 for an unusable rank or a product beyond any file.
std::uint64_t storedCount(const RawEntry& e) {
  if (e.rank < 1 || e.rank > kMaxRank) return 0;
  std::uint64_t n = 1;
  for (std::uint32_t k = 0; k < e.rank; ++k) {
    n *= e.dims[k];
    if (n > kMaxFileBytes) return 0;
  }
  return n;
}

std::string shapeText(const std::vector<int>& shape) {
  std::string s = "[";
  for (std::size_t k = 0; k < shape.size(); ++k) s += (k ? "," : "") + std::to_string(shape[k]);
  return s + "]";
}

std::string shapeText(const RawEntry& e) {
  if (e.rank > kMaxRank) return "[rank " + std::to_string(e.rank) + "]";
  std::string s = "[";
  for (std::uint32_t k = 0; k < e.rank; ++k) s += (k ? "," : "") + std::to_string(e.dims[k]);
  return s + "]";
}

/// If the file is shorter than a self-consistent header says it must be, the message that
/// says so; otherwise nothing (a damaged header is reported as a checksum mismatch).
std::optional<std::string> truncation(const std::vector<std::uint8_t>& bytes) {
  const std::size_t n = bytes.size();
  const std::uint32_t header_size = loadU32(bytes.data() + 12);
  RawHeader h;
  HeaderWalk walk(bytes.data(), std::min<std::size_t>(n, header_size), n < header_size);
  switch (walk.run(h)) {
    case Walk::kShort:
      return "truncated (" + std::to_string(n) + " bytes, header needs " + std::to_string(header_size) + ")";
    case Walk::kBad: return std::nullopt;
    case Walk::kOk: break;
  }
  // The data layout is canonical (each tensor right after the previous one, 64-byte
  // aligned): anything else means the table itself is damaged.
  const std::size_t data_end = n >= kChecksumBytes ? n - kChecksumBytes : 0;
  std::uint64_t expected = alignUp(header_size);
  for (const RawEntry& e : h.table) {
    const std::uint64_t count = storedCount(e);
    if (count == 0 || count != e.count || e.offset != expected) return std::nullopt;
    const std::uint64_t end = e.offset + 4 * count;
    if (end > data_end)
      return "truncated: tensor '" + e.name + "' ends at byte " + std::to_string(end) + " beyond the data's end at byte " +
             std::to_string(data_end) + " (file " + std::to_string(n) + " bytes)";
    expected = alignUp(end);
  }
  if (h.table.empty() && n < std::size_t{header_size} + kChecksumBytes)
    return "truncated (" + std::to_string(n) + " bytes, header and checksum need " +
           std::to_string(std::size_t{header_size} + kChecksumBytes) + ")";
  return std::nullopt;
}

/// The header fields as an architecture; fails naming a field too large to be a dimension.
PolicyArch toArch(const RawHeader& h, const std::string& origin) {
  auto dim = [&](Field f) {
    const std::uint32_t v = h.fields[f];
    if (v > static_cast<std::uint32_t>(std::numeric_limits<int>::max()))
      fail(origin, std::string("header: ") + kFieldNames[f] + " " + std::to_string(v) + " is absurd");
    return static_cast<int>(v);
  };
  PolicyArch a;
  a.d_model = dim(kDModel);
  a.heads = dim(kHeads);
  a.encoder_layers = dim(kEncLayers);
  a.decoder_layers = dim(kDecLayers);
  a.ffn_hidden.clear();
  for (std::uint32_t w : h.ffn) {
    if (w > static_cast<std::uint32_t>(std::numeric_limits<int>::max()))
      fail(origin, "header: ffn hidden width " + std::to_string(w) + " is absurd");
    a.ffn_hidden.push_back(static_cast<int>(w));
  }
  a.tokens = dim(kTokens);
  a.features = dim(kFeatures);
  a.movements = dim(kMovements);
  a.clusters = dim(kClusters);
  a.max_steps = dim(kMaxSteps);
  a.window = dim(kWindow);
  a.chunk = dim(kChunk);
  // The field stays in the format; this runtime has the regression head only.
  if (h.fields[kBins] != 0)
    fail(origin, "header: the model has an action-bins head (bins " + std::to_string(h.fields[kBins]) +
                     "); this runtime runs the regression head only (bins 0)");
  return a;
}

/// Limits a joint can have: finite, lower < upper, a positive velocity limit (a model trained
/// for anything else would be checked against the URDF with meaningless numbers).
std::string jointProblem(const TrainedJoint& j) {
  if (!std::isfinite(j.lower) || !std::isfinite(j.upper) || !std::isfinite(j.velocity))
    return "joint '" + j.name + "' has a non-finite limit";
  if (!(j.lower < j.upper))
    return "joint '" + j.name + "' has lower limit " + number(j.lower) + " rad not below its upper limit " +
           number(j.upper) + " rad";
  if (!(j.velocity > 0.0))
    return "joint '" + j.name + "' has velocity limit " + number(j.velocity) + " rad/s, expected > 0";
  return {};
}

/// The architecture and header contents encodeModel can store, or what is wrong.
std::string encodeProblem(const ModelHeader& h) {
  if (const std::string p = archProblem(h.arch); !p.empty()) return "architecture: " + p;
  if (h.joints.size() != static_cast<std::size_t>(h.arch.tokens))
    return std::to_string(h.joints.size()) + " joints given, the architecture has " + std::to_string(h.arch.tokens) +
           " tokens";
  if (h.movement_names.size() != static_cast<std::size_t>(h.arch.movements))
    return std::to_string(h.movement_names.size()) + " movement names given, the architecture has " +
           std::to_string(h.arch.movements) + " movements";
  auto nameProblem = [](const std::string& what, const std::string& s) -> std::string {
    if (s.empty()) return what + " name is empty";
    if (s.size() >= kNameBytes) return what + " name '" + s + "' is longer than 31 bytes";
    if (s.find('\0') != std::string::npos) return what + " name contains a NUL byte";
    return {};
  };
  for (const TrainedJoint& j : h.joints) {
    if (std::string p = nameProblem("joint", j.name); !p.empty()) return p;
    if (std::string p = jointProblem(j); !p.empty()) return p;
  }
  for (const std::string& m : h.movement_names)
    if (std::string p = nameProblem("movement", m); !p.empty()) return p;
  if (h.metadata_json.size() > std::numeric_limits<std::uint32_t>::max()) return "metadata is larger than 4 GiB";
  if (const std::string p = jsonShapeProblem(h.metadata_json); !p.empty()) return "metadata " + p;
  if (h.conditioning != Conditioning::kReference && h.conditioning != Conditioning::kAutonomous)
    return "conditioning " + std::to_string(static_cast<std::uint32_t>(h.conditioning)) + " is unknown";
  return {};
}

}  // namespace

// ---- ModelFile ------------------------------------------------------------------------------

const float* ModelFile::data(std::size_t index) const {
  assert(index < tensors.size());
  return reinterpret_cast<const float*>((mapped != nullptr ? mapped : bytes.data()) + tensors[index].offset);
}

std::size_t ModelFile::find(const std::string& name) const {
  for (std::size_t i = 0; i < tensors.size(); ++i)
    if (tensors[i].spec.name == name) return i;
  throw ModelFileError("model has no tensor named '" + name + "'");
}

std::uint64_t fnv1a64(const std::uint8_t* data, std::size_t size, std::uint64_t seed) {
  std::uint64_t h = seed;
  for (std::size_t i = 0; i < size; ++i) {
    h ^= data[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

// ---- writing --------------------------------------------------------------------------------

std::vector<std::uint8_t> encodeModel(const ModelHeader& header, const std::vector<std::vector<float>>& tensors) {
  if (const std::string p = encodeProblem(header); !p.empty()) throw ModelFileError("cannot encode model: " + p);
  const std::vector<TensorSpec> manifest = policyManifest(header.arch);
  if (tensors.size() != manifest.size())
    throw ModelFileError("cannot encode model: " + std::to_string(tensors.size()) + " tensors given, the manifest has " +
                         std::to_string(manifest.size()));
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    if (tensors[i].size() != manifest[i].count())
      throw ModelFileError("cannot encode model: tensor " + std::to_string(i) + " '" + manifest[i].name + "' " +
                           shapeText(manifest[i].shape) + " needs " + std::to_string(manifest[i].count()) +
                           " floats, got " + std::to_string(tensors[i].size()));
    for (std::size_t k = 0; k < tensors[i].size(); ++k)
      if (!std::isfinite(tensors[i][k]))
        throw ModelFileError("cannot encode model: tensor '" + manifest[i].name + "' holds NaN/Inf at element " +
                             std::to_string(k));
  }

  const PolicyArch& a = header.arch;
  const std::size_t header_size = kFixedBytes + 4 * a.ffn_hidden.size() + kJointBytes * header.joints.size() +
                                  kNameBytes * header.movement_names.size() + 4 + header.metadata_json.size() + 4 +
                                  kEntryBytes * manifest.size();
  if (header_size > std::numeric_limits<std::uint32_t>::max())
    throw ModelFileError("cannot encode model: header of " + std::to_string(header_size) + " bytes is too large");
  std::vector<std::uint64_t> offsets(manifest.size());
  std::size_t end = header_size;
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    offsets[i] = alignUp(end);
    end = offsets[i] + 4 * manifest[i].count();
  }

  // Zero-initialised: the name padding and the gaps before aligned tensors are zeros, so
  // equal inputs give equal bytes.
  std::vector<std::uint8_t> out(end + kChecksumBytes, 0);
  Writer w(out);
  w.name(std::string(kModelMagic, sizeof kModelMagic), sizeof kModelMagic);
  w.u32(kModelFormatVersion);
  w.u32(static_cast<std::uint32_t>(header_size));
  for (int v : {a.d_model, a.heads, a.encoder_layers, a.decoder_layers, static_cast<int>(a.ffn_hidden.size()), a.tokens,
                a.features, a.movements, a.clusters, a.max_steps, a.window, a.chunk, 0 /* bins */})
    w.u32(static_cast<std::uint32_t>(v));
  w.u32(static_cast<std::uint32_t>(header.conditioning));
  for (int width : a.ffn_hidden) w.u32(static_cast<std::uint32_t>(width));
  for (const TrainedJoint& j : header.joints) {
    w.name(j.name, kNameBytes);
    w.f64(j.lower);
    w.f64(j.upper);
    w.f64(j.velocity);
  }
  for (const std::string& m : header.movement_names) w.name(m, kNameBytes);
  w.u32(static_cast<std::uint32_t>(header.metadata_json.size()));
  w.raw(header.metadata_json);
  w.u32(static_cast<std::uint32_t>(manifest.size()));
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    const TensorSpec& t = manifest[i];
    if (t.name.size() >= kTensorNameBytes || t.shape.size() > static_cast<std::size_t>(kMaxRank))
      throw ModelFileError("cannot encode model: manifest entry '" + t.name + "' does not fit the tensor table");
    w.name(t.name, kTensorNameBytes);
    w.u32(static_cast<std::uint32_t>(t.shape.size()));
    for (int k = 0; k < kMaxRank; ++k)
      w.u32(k < static_cast<int>(t.shape.size()) ? static_cast<std::uint32_t>(t.shape[static_cast<std::size_t>(k)]) : 0u);
    w.u64(offsets[i]);
    w.u64(t.count());
  }
  assert(w.pos() == header_size);

  for (std::size_t i = 0; i < manifest.size(); ++i) {
    std::uint8_t* p = out.data() + offsets[i];
    for (float v : tensors[i]) {
      storeF32(p, v);
      p += 4;
    }
  }
  storeU64(out.data() + end, fnv1a64(out.data(), end));
  return out;
}

std::uint64_t writeModelFile(const std::string& path, const ModelHeader& header,
                             const std::vector<std::vector<float>>& tensors) {
  std::vector<std::uint8_t> bytes;
  try {
    bytes = encodeModel(header, tensors);
  } catch (const ModelFileError& e) {
    fail(path, e.what());
  }

  const std::string problem = writeFileAtomically(path, bytes.data(), bytes.size());
  if (!problem.empty()) fail(path, problem);
  return loadU64(bytes.data() + bytes.size() - kChecksumBytes);
}

void checkModelImage(const std::uint8_t* data, std::size_t size, std::uint64_t expected, const std::string& origin) {
  if (data == nullptr || size < 16 + kChecksumBytes) fail(origin, "truncated (" + std::to_string(size) + " bytes)");
  if (std::memcmp(data, kModelMagic, sizeof kModelMagic) != 0) fail(origin, "not a nao-rt model (bad magic)");
  const std::uint64_t stored = loadU64(data + size - kChecksumBytes);
  const std::uint64_t computed = fnv1a64(data, size - kChecksumBytes);
  if (stored != computed)
    fail(origin, "checksum mismatch (stored " + hex64(stored) + ", computed " + hex64(computed) + ")");
  if (computed != expected)
    fail(origin, "checksum " + hex64(computed) + " is not the " + hex64(expected) + " its generated code describes");
}

ModelFile mappedModelFile(const ModelImage& image, const std::string& origin) {
  if (image.header == nullptr || (image.tensors > 0 && (image.offsets == nullptr || image.extents == nullptr)))
    fail(origin, "no header or tensor table");
  checkModelImage(image.bytes, image.size, image.checksum, origin);
  ModelFile model;
  model.header = *image.header;
  model.checksum = image.checksum;
  model.mapped = image.bytes;
  model.mapped_size = image.size;
  const std::vector<TensorSpec> manifest = policyManifest(model.header.arch);
  if (manifest.size() != image.tensors)
    fail(origin, std::to_string(image.tensors) + " tensor offsets for a manifest of " + std::to_string(manifest.size()));
  const std::size_t end = image.size - kChecksumBytes;
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    const std::uint64_t offset = image.offsets[i];
    const std::size_t bytes = manifest[i].count() * sizeof(float);
    if (offset % kModelAlignment != 0 || offset > end || bytes > end - offset)
      fail(origin, "tensor '" + manifest[i].name + "' at offset " + std::to_string(offset) + " is outside the image");
    const TensorExtent e = viewExtent(manifest[i]);
    if (!(image.extents[i] == e))
      fail(origin, "tensor '" + manifest[i].name + "' has the generated extent [" + std::to_string(image.extents[i].rows) +
                       "," + std::to_string(image.extents[i].cols) + "], the manifest's is [" + std::to_string(e.rows) +
                       "," + std::to_string(e.cols) + "]");
    model.tensors.push_back({manifest[i], offset});
  }
  return model;
}

std::size_t releaseImagePages(const std::uint8_t* data, std::size_t size) noexcept {
#if defined(__linux__)
  const long page_l = sysconf(_SC_PAGESIZE);
  if (data == nullptr || page_l <= 0) return 0;
  const auto page = static_cast<std::uintptr_t>(page_l);
  const auto lo = (reinterpret_cast<std::uintptr_t>(data) + page - 1) / page * page;
  const auto hi = (reinterpret_cast<std::uintptr_t>(data) + size) / page * page;
  if (hi <= lo) return 0;
  // Read-only and never written, so dropping the pages loses nothing: the next read maps the
  // file's bytes again.
  if (madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED) != 0) return 0;
  return hi - lo;
#else
  (void)data;
  (void)size;
  return 0;
#endif
}

// ---- reading --------------------------------------------------------------------------------

ModelFile decodeModel(std::vector<std::uint8_t> bytes, const std::string& origin) {
  const std::size_t n = bytes.size();
  // Magic, then version: read from the file's first 12 bytes. An empty vector may have no
  // storage at all (data() is null, and memcmp on null is undefined even for 0 bytes).
  if (n < sizeof kModelMagic) {
    if (n == 0 || std::memcmp(bytes.data(), kModelMagic, n) == 0)
      fail(origin, "truncated (" + std::to_string(n) + " bytes, header needs at least " +
                       std::to_string(kFixedBytes) + ")");
    fail(origin, "not a nao-rt model (bad magic)");
  }
  if (std::memcmp(bytes.data(), kModelMagic, sizeof kModelMagic) != 0) fail(origin, "not a nao-rt model (bad magic)");
  if (n < 12) fail(origin, "truncated (" + std::to_string(n) + " bytes, header needs at least " + std::to_string(kFixedBytes) + ")");
  const std::uint32_t version = loadU32(bytes.data() + 8);
  if (version != kModelFormatVersion)
    fail(origin, "format version " + std::to_string(version) + " is not supported (this build reads " +
                     std::to_string(kModelFormatVersion) + ")");
  if (n < 16 + kChecksumBytes)
    fail(origin, "truncated (" + std::to_string(n) + " bytes, header needs at least " + std::to_string(kFixedBytes) + ")");
  if (n > kMaxFileBytes) fail(origin, "file of " + std::to_string(n) + " bytes is larger than any model");

  // Checksum before anything else is believed. When it fails, a header that is consistent
  // with itself but describes a longer file means the file was cut short: say that instead.
  const std::uint64_t stored = loadU64(bytes.data() + n - kChecksumBytes);
  const std::uint64_t computed = fnv1a64(bytes.data(), n - kChecksumBytes);
  if (stored != computed) {
    if (std::optional<std::string> t = truncation(bytes)) fail(origin, *t);
    fail(origin, "checksum mismatch (stored " + hex64(stored) + ", computed " + hex64(computed) + ")");
  }

  // Header (every read bounded by the stored header size, itself inside the file).
  const std::uint32_t header_size = loadU32(bytes.data() + 12);
  if (std::size_t{header_size} + kChecksumBytes > n)
    fail(origin, "truncated (" + std::to_string(n) + " bytes, header needs " + std::to_string(header_size) + ")");
  RawHeader raw;
  HeaderWalk walk(bytes.data(), header_size, false);
  if (walk.run(raw) != Walk::kOk) fail(origin, "header: " + walk.problem());

  ModelFile model;
  ModelHeader& h = model.header;
  h.arch = toArch(raw, origin);
  const std::uint32_t cond = raw.fields[kConditioning];
  if (cond != static_cast<std::uint32_t>(Conditioning::kReference) &&
      cond != static_cast<std::uint32_t>(Conditioning::kAutonomous))
    fail(origin, "header: conditioning " + std::to_string(cond) + " is neither 0 (reference) nor 1 (autonomous)");
  h.conditioning = static_cast<Conditioning>(cond);
  for (const TrainedJoint& j : raw.joints)
    if (const std::string p = jointProblem(j); !p.empty()) fail(origin, "header: " + p);
  h.joints = std::move(raw.joints);
  h.movement_names = std::move(raw.movements);
  // The metadata is JSON that nao_rt --info parses and dumps, recursively: bound its nesting.
  if (const std::string p = jsonShapeProblem(raw.metadata); !p.empty()) fail(origin, "header: metadata " + p);
  h.metadata_json = std::move(raw.metadata);

  if (const std::string p = archProblem(h.arch); !p.empty()) fail(origin, "architecture: " + p);

  // The tensor table must be the manifest of this architecture, laid out canonically.
  const std::vector<TensorSpec> manifest = policyManifest(h.arch);
  if (raw.table.size() != manifest.size())
    fail(origin, "tensor table has " + std::to_string(raw.table.size()) + " entries, the manifest of this architecture has " +
                     std::to_string(manifest.size()));
  const std::size_t data_end = n - kChecksumBytes;
  std::uint64_t expected_offset = alignUp(header_size);
  model.tensors.resize(manifest.size());
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    const RawEntry& e = raw.table[i];
    const TensorSpec& m = manifest[i];
    const std::string at = "tensor " + std::to_string(i) + " ";
    bool same_shape = e.rank == m.shape.size();
    for (std::size_t k = 0; same_shape && k < m.shape.size(); ++k)
      same_shape = e.dims[k] == static_cast<std::uint32_t>(m.shape[k]);
    if (e.name != m.name || !same_shape) {
      std::string what = at + "is '" + e.name + "' " + shapeText(e) + ", the manifest expects '" + m.name + "' " +
                         shapeText(m.shape);
      if (e.name != m.name) {
        const auto it = std::find_if(manifest.begin(), manifest.end(), [&](const TensorSpec& t) { return t.name == e.name; });
        what += it == manifest.end() ? " (no such tensor in the manifest)"
                                     : " (out of order: the manifest has '" + e.name + "' at position " +
                                           std::to_string(it - manifest.begin()) + ")";
      }
      fail(origin, what);
    }
    for (std::uint32_t k = e.rank; k < kMaxRank; ++k)
      if (e.dims[k] != 0) fail(origin, at + "'" + e.name + "' has a nonzero dimension beyond its rank");
    if (e.count != m.count())
      fail(origin, at + "'" + e.name + "' says " + std::to_string(e.count) + " elements, its shape " + shapeText(m.shape) +
                       " holds " + std::to_string(m.count()));
    if (e.offset != expected_offset)
      fail(origin, at + "'" + e.name + "' starts at byte " + std::to_string(e.offset) + ", expected " +
                       std::to_string(expected_offset) + " (64-byte aligned, right after the previous tensor)");
    const std::uint64_t end = e.offset + 4 * e.count;
    if (end > data_end)
      fail(origin, "truncated: tensor '" + e.name + "' ends at byte " + std::to_string(end) +
                       " beyond the data's end at byte " + std::to_string(data_end) + " (file " + std::to_string(n) +
                       " bytes)");
    expected_offset = alignUp(end);
    model.tensors[i].spec = m;
    model.tensors[i].offset = e.offset;
  }
  const std::uint64_t last_end = manifest.empty() ? header_size : model.tensors.back().offset + 4 * manifest.back().count();
  if (last_end != data_end)
    fail(origin, std::to_string(data_end - last_end) + " unexpected bytes between the last tensor (ends at byte " +
                     std::to_string(last_end) + ") and the checksum");

  // Every weight finite.
  for (std::size_t i = 0; i < model.tensors.size(); ++i) {
    const std::uint8_t* p = bytes.data() + model.tensors[i].offset;
    const std::size_t count = model.tensors[i].spec.count();
    for (std::size_t k = 0; k < count; ++k) {
      const float v = loadF32(p + 4 * k);
      if (!std::isfinite(v))
        fail(origin, "tensor '" + model.tensors[i].spec.name + "' holds NaN/Inf at element " + std::to_string(k) + " (" +
                         (std::isnan(v) ? "NaN" : v > 0 ? "+Inf" : "-Inf") + ")");
    }
  }

  model.checksum = stored;
  model.bytes = std::move(bytes);
  return model;
}

ModelFile readModelFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(path, std::string("cannot open (") + std::strerror(errno) + ")");
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    fail(path, "not a regular file");
  }
  if (static_cast<std::uint64_t>(st.st_size) > kMaxFileBytes) {
    ::close(fd);
    fail(path, "file of " + std::to_string(st.st_size) + " bytes is larger than any model");
  }
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(st.st_size));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t got = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) {
      const int err = errno;
      ::close(fd);
      fail(path, std::string("cannot read (") + std::strerror(err) + ")");
    }
    if (got == 0) break;  // the file shrank while we read it: decode what is there
    done += static_cast<std::size_t>(got);
  }
  ::close(fd);
  bytes.resize(done);
  return decodeModel(std::move(bytes), path);
}

// ---- joints ---------------------------------------------------------------------------------

std::vector<JointVector> modelKeyPoses(const ModelFile& model, int m) {
  const PolicyArch& a = model.header.arch;
  const float* c = model.data(model.find("centroids"));
  std::vector<JointVector> out;
  for (int k = 0; k < a.clusters; ++k) {
    JointVector q;
    for (int j = 0; j < kNumJoints; ++j)
      q[j] = static_cast<double>(c[(static_cast<std::size_t>(m) * a.clusters + k) * a.tokens + j]);
    out.push_back(q);
  }
  return out;
}

void checkJointsMatch(const ModelFile& model, const ArmModel& arm, const std::string& origin) {
  const std::vector<TrainedJoint>& joints = model.header.joints;
  if (joints.size() != static_cast<std::size_t>(kNumJoints))
    fail(origin, "the model was trained for " + std::to_string(joints.size()) + " joints, the arm has " +
                     std::to_string(kNumJoints));
  for (int j = 0; j < kNumJoints; ++j) {
    const TrainedJoint& t = joints[static_cast<std::size_t>(j)];
    if (t.name != kJointNames[static_cast<std::size_t>(j)])
      fail(origin, "joint " + std::to_string(j) + " is '" + t.name + "' in the model, '" +
                       kJointNames[static_cast<std::size_t>(j)] + "' in the URDF");
    const struct {
      const char* what;
      double model, urdf;
      const char* unit;
    } limits[] = {{"lower limit", t.lower, arm.q_min[j], "rad"},
                  {"upper limit", t.upper, arm.q_max[j], "rad"},
                  {"velocity limit", t.velocity, arm.v_max[j], "rad/s"}};
    for (const auto& l : limits)
      if (!(std::abs(l.model - l.urdf) <= kJointTolerance))
        fail(origin, "joint '" + t.name + "' " + l.what + " is " + number(l.model) + " " + l.unit + " in the model, " +
                         number(l.urdf) + " " + l.unit + " in the URDF");
  }
}

std::vector<TrainedJoint> trainedJoints(const ArmModel& arm) {
  std::vector<TrainedJoint> out;
  out.reserve(kNumJoints);
  for (int j = 0; j < kNumJoints; ++j)
    out.push_back({kJointNames[static_cast<std::size_t>(j)], arm.q_min[j], arm.q_max[j], arm.v_max[j]});
  return out;
}

}  // namespace nao
