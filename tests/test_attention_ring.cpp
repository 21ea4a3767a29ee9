// The attention ring: single-writer seqlock ring, in process, in POSIX shared
// memory (same process and a forked reader process), and its attention.bin dump.
#include "nao/attention_ring.hpp"
#include "nao/attention_shm.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

using namespace nao;

namespace {

using PaperPayload = AttentionPayload<4, 4, 128, 20>;  // paper architecture: 4 decoder layers, 4 heads, d 128
using SmallPayload = AttentionPayload<2, 4, 32, 8>;   // small test architecture
using PaperRing = AttentionRing<PaperPayload>;
using SmallRing = AttentionRing<SmallPayload>;

// Fills every field from the generator, tick as given, and seals it.
template <typename P>
void fillPayload(P& p, std::uint64_t tick, std::mt19937_64& rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  p.tick = tick;
  p.fault = static_cast<std::uint32_t>(rng() & 0xffu);
  p.reserved = 0;
  for (float& v : p.score) v = u(rng);
  for (float& v : p.mass) v = u(rng);
  for (float& v : p.age_profile) v = u(rng);
  for (auto& l : p.cross)
    for (auto& h : l)
      for (auto& i : h)
        for (float& v : i) v = u(rng);
  for (auto& i : p.cross_out)
    for (float& v : i) v = u(rng);
  sealPayload(p);
}

// A shared-memory name no other test (or parallel test run) uses.
std::string shmName(const char* what) { return "/nao_rt_test_attn_" + std::to_string(::getpid()) + "_" + what; }

std::string tempPath(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests";
  std::filesystem::create_directories(dir);
  return (dir / (std::to_string(::getpid()) + "_" + name)).string();
}

std::vector<unsigned char> readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// Independent little-endian decoding for the file checks (not the writer's code).
std::uint64_t le(const unsigned char* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

// What a reader thread saw.
struct ReaderTally {
  std::int64_t reads = 0, ok = 0, ok_while_writing = 0, not_yet = 0, overwritten = 0, torn = 0;
  std::int64_t bad_checksum = 0, bad_tick = 0;
  std::int64_t raw_copies = 0, raw_torn = 0;  // unchecked copies, to show tearing really happens
  std::int64_t pushes = 0;                     // how many records the writer pushed meanwhile
};

// Reads the newest and the oldest record (the one the writer replaces next) as fast as it can
// until `done`, checking every kOk copy. Also makes unchecked raw copies of the slot the
// writer fills next, counting the ones whose checksum fails: what the seqlock protects from.
template <typename Ring>
void hammer(const Ring& ring, const std::atomic<bool>& done, std::atomic<bool>& started,
            std::atomic<std::int64_t>& passes, ReaderTally& t, std::uint64_t tick_offset) {
  using P = typename Ring::payload_type;
  auto out = std::make_unique<P>();
  auto raw = std::make_unique<P>();
  started.store(true);
  auto check = [&](std::uint64_t record, bool writing) {
    ++t.reads;
    switch (readFromNonRT(ring, record, *out)) {
      case AttentionRead::kOk:
        ++t.ok;
        t.ok_while_writing += writing;
        t.bad_checksum += !payloadIntact(*out);
        t.bad_tick += out->tick != record + tick_offset;
        break;
      case AttentionRead::kNotYetWritten: ++t.not_yet; break;
      case AttentionRead::kOverwritten: ++t.overwritten; break;
      case AttentionRead::kTorn: ++t.torn; break;
    }
  };
  bool writing = true;
  while (writing) {
    writing = !done.load();
    const std::uint64_t n = recordsWritten(ring);
    if (n > 0) check(n - 1, writing);
    check(oldestRecord(ring), writing);
    check(n, writing);  // usually not yet written, sometimes just completed
    std::memcpy(static_cast<void*>(raw.get()), &ring.slots[n % Ring::kCapacity].payload, sizeof(P));
    ++t.raw_copies;
    t.raw_torn += !payloadIntact(*raw);
    passes.store(t.raw_copies, std::memory_order_relaxed);
  }
}

// Writer side of the hammering tests: at least n pushes of random sealed payloads (tick =
// record + offset), and on until the reader has made 200 passes, so that a reader that waits
// for a core on a busy machine still reads while the writer pushes. The cap bounds a stuck reader.
template <typename Ring>
ReaderTally pushWhileHammered(Ring& ring, int n_pushes, std::uint64_t tick_offset, std::uint64_t seed) {
  using P = typename Ring::payload_type;
  std::atomic<bool> done{false}, started{false};
  std::atomic<std::int64_t> passes{0};
  ReaderTally tally;
  std::thread reader([&] { hammer(ring, done, started, passes, tally, tick_offset); });
  while (!started.load()) std::this_thread::yield();
  std::mt19937_64 rng(seed);
  auto p = std::make_unique<P>();
  std::int64_t i = 0;
  for (; i < 1000LL * n_pushes && (i < n_pushes || passes.load(std::memory_order_relaxed) < 200); ++i) {
    fillPayload(*p, static_cast<std::uint64_t>(i) + tick_offset, rng);
    pushFromRT(ring, *p);
  }
  done.store(true);
  reader.join();
  tally.pushes = i;
  return tally;
}

}  // namespace

TEST_CASE("the ring keeps the last Capacity records in push order; older ones read as overwritten") {
  auto ring = std::make_unique<SmallRing>(attentionPayloadDescriptor<SmallPayload>());
  constexpr std::uint64_t kCap = SmallRing::kCapacity;
  static_assert(kCap >= 1024, "default capacity holds at least 1024 ticks");
  SmallPayload out;
  CHECK(recordsWritten(*ring) == 0);
  CHECK_FALSE(latestRecord(*ring).has_value());
  CHECK(readFromNonRT(*ring, 0, out) == AttentionRead::kNotYetWritten);

  std::mt19937_64 rng(1);
  SmallPayload p;
  for (std::uint64_t i = 0; i < kCap; ++i) {
    fillPayload(p, 100 + i, rng);
    CHECK(pushFromRT(*ring, p) == i);
  }
  REQUIRE(latestRecord(*ring) == kCap - 1);
  CHECK(oldestRecord(*ring) == 0);
  for (std::uint64_t r = 0; r < kCap; ++r) {
    REQUIRE(readFromNonRT(*ring, r, out) == AttentionRead::kOk);
    CHECK(out.tick == 100 + r);
    CHECK(payloadIntact(out));
  }
  CHECK(readFromNonRT(*ring, kCap, out) == AttentionRead::kNotYetWritten);

  // One more push replaces record 0 (same slot), and only record 0.
  fillPayload(p, 100 + kCap, rng);
  pushFromRT(*ring, p);
  CHECK(readFromNonRT(*ring, 0, out) == AttentionRead::kOverwritten);
  CHECK(readFromNonRT(*ring, 1, out) == AttentionRead::kOk);
  CHECK(readFromNonRT(*ring, kCap, out) == AttentionRead::kOk);
  CHECK(out.tick == 100 + kCap);
  CHECK(oldestRecord(*ring) == 1);
  CHECK(latestRecord(*ring) == kCap);

  // Capacity more pushes later, every earlier record is gone.
  for (std::uint64_t i = 0; i < kCap; ++i) pushFromRT(*ring, p);
  for (std::uint64_t r = 0; r <= kCap; ++r) REQUIRE(readFromNonRT(*ring, r, out) == AttentionRead::kOverwritten);
  CHECK(readFromNonRT(*ring, kCap + 1, out) == AttentionRead::kOk);
  CHECK_FALSE(isClosed(ring->header));
  closeFromRT(*ring);
  CHECK(isClosed(ring->header));
}

TEST_CASE("the ring block and the payload have the documented layout") {
  const auto ring = std::make_unique<PaperRing>(attentionPayloadDescriptor<PaperPayload>());
  const AttentionRingHeader& h = ring->header;
  CHECK(h.magic.load() == kAttentionRingMagic);
  char magic[8];
  std::memcpy(magic, &h.magic, 8);
  CHECK(std::string(magic, 8) == "NAORING1");
  CHECK(h.layout_version == kAttentionRingLayoutVersion);
  CHECK(h.capacity == 1024);
  CHECK(h.payload_bytes == sizeof(PaperPayload));
  CHECK(h.header_bytes == sizeof(AttentionRingHeader));
  CHECK(h.slot_bytes % kCacheLineBytes == 0);
  CHECK(h.payload_offset == 8);
  CHECK(h.total_bytes == sizeof(PaperRing));
  CHECK(reinterpret_cast<std::uintptr_t>(&ring->slots[0]) % kCacheLineBytes == 0);
  CHECK(reinterpret_cast<std::uintptr_t>(&ring->slots[1]) % kCacheLineBytes == 0);
  const std::uint32_t want[8] = {kAttentionPayloadFormat, 4, 4, 5, 128, 20, 0, 0};
  for (int i = 0; i < 8; ++i) CHECK(h.descriptor[i] == want[i]);
  CHECK(kAttentionPayloadFormat == 2);

  // Paper payload: 16 + 4 (5 + 5 + 20 + 4*4*25 + 5*128) = 4296 bytes of data, no padding, checksum.
  CHECK(offsetof(PaperPayload, score) == 16);
  CHECK(offsetof(PaperPayload, mass) == 36);
  CHECK(offsetof(PaperPayload, age_profile) == 56);
  CHECK(offsetof(PaperPayload, cross) == 136);
  CHECK(offsetof(PaperPayload, cross_out) == 136 + 4 * 4 * 4 * 25);
  CHECK(offsetof(PaperPayload, checksum) == 4296);
  CHECK(sizeof(PaperPayload) == 4304);
  CHECK(validateAttentionRing(ring.get(), sizeof(PaperRing), "in-process").header == &ring->header);
}

TEST_CASE("sealPayload zeroes the padding and sets a checksum that any changed byte breaks") {
  PaperPayload a;
  std::memset(static_cast<void*>(&a), 0xAB, sizeof a);  // garbage in the padding too
  std::mt19937_64 rng(3);
  fillPayload(a, 7, rng);
  CHECK(payloadIntact(a));
  // The paper payload has no padding (4296 bytes of data, a multiple of 8).
  static_assert(offsetof(PaperPayload, checksum) == 4296);
  CHECK(a.checksum == attentionFnv1a64(&a, 4296));
  for (std::size_t at : {std::size_t{0}, std::size_t{16}, std::size_t{60}, std::size_t{2000}, std::size_t{4295}}) {
    PaperPayload b = a;
    reinterpret_cast<unsigned char*>(&b)[at] ^= 1;
    CHECK_MESSAGE(!payloadIntact(b), "flipping byte " << at << " left the checksum valid");
  }
  // A payload with padding: L 1, H 1, D 4, W 3: 16 + 4 (5 + 5 + 3 + 25 + 20) = 248 bytes of
  // data... a multiple of 8 too; W 2 gives 244 and 4 bytes of padding.
  using PaddedPayload = AttentionPayload<1, 1, 4, 2>;
  static_assert(offsetof(PaddedPayload, checksum) == 248);
  PaddedPayload pp;
  std::memset(static_cast<void*>(&pp), 0xAB, sizeof pp);
  fillPayload(pp, 3, rng);
  const auto* pb = reinterpret_cast<const unsigned char*>(&pp);
  for (std::size_t i = 244; i < 248; ++i) CHECK(pb[i] == 0);
  CHECK(pp.checksum == attentionFnv1a64(&pp, 248));
  // FNV-1a 64 reference values ("" and "a").
  CHECK(attentionFnv1a64("", 0) == 0xcbf29ce484222325ull);
  CHECK(attentionFnv1a64("a", 1) == 0xaf63dc4c8601ec8cull);
}

TEST_CASE("a slot left half-written is reported torn after bounded retries, never as a record") {
  auto ring = std::make_unique<SmallRing>();
  std::mt19937_64 rng(5);
  SmallPayload p, out;
  for (std::uint64_t i = 0; i < 10; ++i) {
    fillPayload(p, i, rng);
    pushFromRT(*ring, p);
  }
  auto& seq = ring->slots[4].seq;
  REQUIRE(seq.load() == 2 * 4 + 2);
  // What a writer that stopped in the middle of record 4's copy leaves behind.
  seq.store(2 * 4 + 1);
  CHECK(readFromNonRT(*ring, 4, out) == AttentionRead::kTorn);
  CHECK(readFromNonRT(attentionRingView(*ring), 4, &out) == AttentionRead::kTorn);
  CHECK(readFromNonRT(*ring, 3, out) == AttentionRead::kOk);
  // A write of a later record into the slot: the record is gone, not torn.
  seq.store(2 * (4 + SmallRing::kCapacity) + 1);
  CHECK(readFromNonRT(*ring, 4, out) == AttentionRead::kOverwritten);
  seq.store(2 * 4 + 2);
  REQUIRE(readFromNonRT(*ring, 4, out) == AttentionRead::kOk);
  CHECK(out.tick == 4);
  // The record being pushed right now (not yet counted) is not yet written, not torn.
  ring->slots[10].seq.store(2 * 10 + 1);
  CHECK(readFromNonRT(*ring, 10, out) == AttentionRead::kNotYetWritten);
  CHECK(readFromNonRT(*ring, 11, out) == AttentionRead::kNotYetWritten);
}

TEST_CASE("a reader thread hammering the ring during 10,000 pushes or more only ever gets intact records") {
  auto ring = std::make_unique<PaperRing>(attentionPayloadDescriptor<PaperPayload>());
  const ReaderTally t = pushWhileHammered(*ring, 10000, 1000, 21);
  MESSAGE("reads " << t.reads << ": ok " << t.ok << " (" << t.ok_while_writing << " while writing), not yet "
                   << t.not_yet << ", overwritten " << t.overwritten << ", torn " << t.torn << "; raw unchecked copies "
                   << t.raw_copies << ", of which torn " << t.raw_torn);
  CHECK_MESSAGE(t.bad_checksum == 0, t.bad_checksum << " records read as ok had a bad checksum");
  CHECK_MESSAGE(t.bad_tick == 0, t.bad_tick << " records read as ok carried the wrong tick");
  CHECK(t.torn == 0);
  CHECK_MESSAGE(t.ok_while_writing > 0, "the reader got no record while the writer was pushing");
  CHECK(recordsWritten(*ring) == static_cast<std::uint64_t>(t.pushes));
  CHECK(t.pushes >= 10000);
}

TEST_CASE("with a 4-slot ring the reader races the writer constantly and still gets only intact records") {
  // The writer laps this ring every 4 pushes, so reads of the oldest record keep colliding
  // with the writer: the seqlock has to reject those copies.
  auto ring = std::make_unique<AttentionRing<PaperPayload, 4>>();
  const ReaderTally t = pushWhileHammered(*ring, 20000, 0, 22);
  MESSAGE("reads " << t.reads << ": ok " << t.ok << ", overwritten " << t.overwritten << ", torn " << t.torn
                   << "; raw unchecked copies " << t.raw_copies << ", of which torn " << t.raw_torn);
  CHECK_MESSAGE(t.bad_checksum == 0, t.bad_checksum << " records read as ok had a bad checksum");
  CHECK_MESSAGE(t.bad_tick == 0, t.bad_tick << " records read as ok carried the wrong tick");
  CHECK(t.torn == 0);
  CHECK(t.ok > 0);
}

TEST_CASE("a ring in shared memory written through the creator reads back through a read-only mapping") {
  const std::string name = shmName("roundtrip");
  SharedAttentionRing<SmallRing> writer(name.substr(1), attentionPayloadDescriptor<SmallPayload>());  // '/' prepended
  CHECK(writer.shm().name() == name);
  CHECK(writer.shm().isCreator());
  MESSAGE("mlock of the shared ring: " << std::string(writer.shm().locked() ? "succeeded" : "not permitted"));

  AttentionShm reader_shm = AttentionShm::openReadOnly(name);
  CHECK_FALSE(reader_shm.isCreator());
  CHECK(reader_shm.writableData() == nullptr);
  const SmallRing& reader = attachAttentionRing<SmallRing>(reader_shm);
  CHECK(static_cast<const void*>(&reader) != static_cast<const void*>(&writer.ring()));
  CHECK(reader.header.descriptor[4] == 32);

  std::mt19937_64 rng(9);
  SmallPayload p, out;
  for (std::uint64_t i = 0; i < 1500; ++i) {
    fillPayload(p, i, rng);
    pushFromRT(writer.ring(), p);
  }
  CHECK(recordsWritten(reader) == 1500);
  CHECK(readFromNonRT(reader, 1499, out) == AttentionRead::kOk);
  CHECK(std::memcmp(&out, &p, sizeof p) == 0);
  CHECK(readFromNonRT(reader, 100, out) == AttentionRead::kOverwritten);
  std::vector<unsigned char> raw(reader_shm.view().header->payload_bytes);
  REQUIRE(readFromNonRT(reader_shm.view(), 1000, raw.data()) == AttentionRead::kOk);
  CHECK(le(raw.data(), 8) == 1000);

  // The reader's mapping really is read-only: a store into it kills a child with SIGSEGV.
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    std::signal(SIGSEGV, SIG_DFL);  // die quietly, not through doctest's crash report
    *static_cast<volatile unsigned char*>(const_cast<void*>(reader_shm.data())) = 0;
    ::_exit(0);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  CHECK(WIFSIGNALED(status));
  if (WIFSIGNALED(status)) CHECK(WTERMSIG(status) == SIGSEGV);
}

TEST_CASE("the creator's destructor closes the ring and unlinks the name; readers keep their records") {
  const std::string name = shmName("unlink");
  std::optional<SharedAttentionRing<SmallRing>> writer;
  writer.emplace(name, attentionPayloadDescriptor<SmallPayload>());
  SmallPayload p;
  std::mt19937_64 rng(4);
  fillPayload(p, 77, rng);
  pushFromRT(writer->ring(), p);
  AttentionShm reader_shm = AttentionShm::openReadOnly(name);
  writer.reset();
  CHECK_THROWS_WITH_AS(AttentionShm::openReadOnly(name), doctest::Contains("no shared-memory region"), std::runtime_error);
  const SmallRing& reader = attachAttentionRing<SmallRing>(reader_shm);
  CHECK(isClosed(reader.header));
  SmallPayload out;
  REQUIRE(readFromNonRT(reader, 0, out) == AttentionRead::kOk);
  CHECK(out.tick == 77);
}

TEST_CASE("a stale region of the same name is replaced by a new writer") {
  const std::string name = shmName("stale");
  const int fd = ::shm_open(name.c_str(), O_CREAT | O_RDWR, 0600);
  REQUIRE(fd >= 0);
  REQUIRE(::ftruncate(fd, 100) == 0);
  ::close(fd);
  SharedAttentionRing<SmallRing> writer(name, attentionPayloadDescriptor<SmallPayload>());
  AttentionShm reader_shm = AttentionShm::openReadOnly(name);
  CHECK(reader_shm.size() == sizeof(SmallRing));
}

TEST_CASE("a child process reads the ring by name while the parent writes 10,000 records") {
  const std::string name = shmName("fork");
  SharedAttentionRing<PaperRing> writer(name, attentionPayloadDescriptor<PaperPayload>());
  int ready[2];
  REQUIRE(::pipe(ready) == 0);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // Child: no doctest here; the exit code is the report.
    //   0 ok, 10 open failed, 11 a record read as ok was damaged or had the wrong tick,
    //   12 a torn read, 13 no record read, 14 the writer never closed the ring.
    ::close(ready[0]);
    int code = 0;
    try {
      AttentionShm shm = AttentionShm::openReadOnly(name);
      const PaperRing& ring = attachAttentionRing<PaperRing>(shm);
      auto out = std::make_unique<PaperPayload>();
      const char byte = 1;
      if (::write(ready[1], &byte, 1) != 1) ::_exit(10);
      std::int64_t n_ok = 0;
      std::uint64_t next = 0;
      code = 14;
      for (std::int64_t spin = 0; spin < 2'000'000'000; ++spin) {
        const bool closed = isClosed(ring.header);
        const std::uint64_t n = recordsWritten(ring);
        if (next < oldestRecord(ring)) next = oldestRecord(ring);
        for (; next < n; ++next) {
          const AttentionRead s = readFromNonRT(ring, next, *out);
          if (s == AttentionRead::kTorn) ::_exit(12);
          if (s != AttentionRead::kOk) continue;
          ++n_ok;
          if (!payloadIntact(*out) || out->tick != next) ::_exit(11);
        }
        if (closed && next >= recordsWritten(ring)) {
          code = n_ok > 0 ? 0 : 13;
          break;
        }
      }
    } catch (...) {
      code = 10;
    }
    ::_exit(code);
  }
  ::close(ready[1]);
  char byte = 0;
  const ssize_t got = ::read(ready[0], &byte, 1);
  ::close(ready[0]);
  std::mt19937_64 rng(31);
  auto p = std::make_unique<PaperPayload>();
  for (std::uint64_t i = 0; i < 10000; ++i) {
    fillPayload(*p, i, rng);
    pushFromRT(writer.ring(), *p);
  }
  closeFromRT(writer.ring());
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  CHECK_MESSAGE(got == 1, "the child did not signal that it opened the ring");
  REQUIRE(WIFEXITED(status));
  CHECK_MESSAGE(WEXITSTATUS(status) == 0, "child reader exit code " << WEXITSTATUS(status)
                                                                    << " (10 open, 11 bad record, 12 torn, 13 nothing read, 14 never closed)");
}

TEST_CASE("attention.bin holds the documented header and the ring's records in record order") {
  auto ring = std::make_unique<SmallRing>(attentionPayloadDescriptor<SmallPayload>());
  std::mt19937_64 rng(41);
  std::vector<SmallPayload> pushed(1500);
  for (std::uint64_t i = 0; i < pushed.size(); ++i) {
    fillPayload(pushed[i], 5000 + i, rng);
    pushFromRT(*ring, pushed[i]);
  }
  const std::string path = tempPath("attention.bin");
  const AttentionFileSummary s = writeAttentionFile(path, *ring);
  CHECK(s.first_record == 1500 - 1024);
  CHECK(s.record_count == 1024);
  CHECK(s.records_written == 1500);

  const std::vector<unsigned char> f = readBytes(path);
  const std::size_t payload_bytes = sizeof(SmallPayload);
  REQUIRE(f.size() == 96 + 1024 * payload_bytes);
  const unsigned char* h = f.data();
  CHECK(std::string(reinterpret_cast<const char*>(h), 8) == "NAOATTN1");
  CHECK(le(h + 8, 4) == 1);        // version
  CHECK(le(h + 12, 4) == 96);      // header bytes
  CHECK(le(h + 16, 8) == 1024);    // record count
  CHECK(le(h + 24, 8) == 476);     // first record
  CHECK(le(h + 32, 8) == payload_bytes);
  CHECK(le(h + 40, 8) == 1024);    // ring capacity
  CHECK(le(h + 48, 8) == 1500);    // records written
  const std::uint64_t want_desc[8] = {2, 2, 4, 5, 32, 8, 0, 0};  // format, L, H, tokens, d_model, window
  for (int i = 0; i < 8; ++i) CHECK(le(h + 56 + 4 * i, 4) == want_desc[i]);
  CHECK(le(h + 88, 8) == 0);
  // Payload bytes as pushed; parse the fixed fields and the checksum independently.
  const std::size_t n_data = 16 + 4 * (5 + 5 + 8 + 2 * 4 * 25 + 5 * 32);
  for (std::size_t i = 0; i < 1024; ++i) {
    const unsigned char* rec = f.data() + 96 + i * payload_bytes;
    REQUIRE(std::memcmp(rec, &pushed[476 + i], payload_bytes) == 0);
    CHECK(le(rec, 8) == 5000 + 476 + i);
    float score0;
    std::memcpy(&score0, rec + 16, 4);
    CHECK(score0 == pushed[476 + i].score[0]);
    std::uint64_t fnv = 0xcbf29ce484222325ull;
    for (std::size_t b = 0; b < payload_bytes - 8; ++b) fnv = (fnv ^ rec[b]) * 0x100000001b3ull;
    CHECK(le(rec + payload_bytes - 8, 8) == fnv);
    if (i == 0) CHECK(payload_bytes - 8 - n_data == (n_data % 8 == 0 ? 0 : 8 - n_data % 8));
  }

  // An empty ring: the header alone.
  auto empty = std::make_unique<SmallRing>(attentionPayloadDescriptor<SmallPayload>());
  writeAttentionFile(path, *empty);
  const std::vector<unsigned char> e = readBytes(path);
  REQUIRE(e.size() == 96);
  CHECK(le(e.data() + 16, 8) == 0);
  CHECK(le(e.data() + 24, 8) == 0);
  std::filesystem::remove(path);
}

TEST_CASE("the same pushes give a byte-identical attention.bin, through the ring or a shared-memory reader") {
  auto run = [](std::uint64_t seed, const std::string& path, int garbage) {
    auto ring = std::make_unique<PaperRing>(attentionPayloadDescriptor<PaperPayload>());
    std::mt19937_64 rng(seed);
    PaperPayload p;
    // Different garbage in the padding each run: sealPayload must zero it.
    std::memset(static_cast<void*>(&p), garbage, sizeof p);
    for (std::uint64_t i = 0; i < 1300; ++i) {
      fillPayload(p, i, rng);
      pushFromRT(*ring, p);
    }
    writeAttentionFile(path, *ring);
    return readBytes(path);
  };
  const std::string a = tempPath("a.bin"), b = tempPath("b.bin"), c = tempPath("c.bin"), d = tempPath("d.bin");
  const auto fa = run(77, a, 0x5A);
  const auto fb = run(77, b, 0xC3);
  const auto fc = run(78, c, 0x5A);
  CHECK(fa.size() == 96 + 1024 * sizeof(PaperPayload));
  CHECK_MESSAGE(fa == fb, "two runs with the same pushes wrote different attention.bin files");
  CHECK(fa != fc);

  // The same records dumped by a reader through the read-only shared mapping.
  const std::string name = shmName("dump");
  SharedAttentionRing<PaperRing> writer(name, attentionPayloadDescriptor<PaperPayload>());
  std::mt19937_64 rng(77);
  PaperPayload p;
  for (std::uint64_t i = 0; i < 1300; ++i) {
    fillPayload(p, i, rng);
    pushFromRT(writer.ring(), p);
  }
  AttentionShm reader = AttentionShm::openReadOnly(name);
  writeAttentionFile(d, reader.view());
  CHECK(readBytes(d) == fa);
  for (const auto& path : {a, b, c, d}) std::filesystem::remove(path);
}

TEST_CASE("opening a missing name, a small region or a region that is not a ring fails naming the region") {
  const std::string missing = shmName("missing");
  CHECK_THROWS_WITH_AS(AttentionShm::openReadOnly(missing), doctest::Contains(("attention ring " + missing + ": no shared-memory region").c_str()),
                       std::runtime_error);

  const std::string small = shmName("small");
  const std::string zeros = shmName("zeros");
  for (const auto& [name, bytes] : {std::pair{small, 100}, std::pair{zeros, 1 << 20}}) {
    ::shm_unlink(name.c_str());
    const int fd = ::shm_open(name.c_str(), O_CREAT | O_EXCL | O_RDWR, 0600);
    REQUIRE(fd >= 0);
    REQUIRE(::ftruncate(fd, bytes) == 0);
    ::close(fd);
  }
  CHECK_THROWS_WITH_AS(AttentionShm::openReadOnly(small), doctest::Contains((small + ": region of 100 bytes is smaller").c_str()),
                       std::runtime_error);
  CHECK_THROWS_WITH_AS(AttentionShm::openReadOnly(zeros), doctest::Contains((zeros + ": not a nao-rt attention ring").c_str()),
                       std::runtime_error);
  ::shm_unlink(small.c_str());
  ::shm_unlink(zeros.c_str());

  // A ring, but not the one this program was built for.
  const std::string other = shmName("other");
  SharedAttentionRing<SmallRing> writer(other, attentionPayloadDescriptor<SmallPayload>());
  AttentionShm reader = AttentionShm::openReadOnly(other);
  CHECK_THROWS_WITH_AS(attachAttentionRing<PaperRing>(reader),
                       doctest::Contains(("attention ring " + other + ": payload size is " + std::to_string(sizeof(SmallPayload))).c_str()),
                       std::runtime_error);

  // A truncated ring: the header promises more bytes than the region holds.
  auto ring = std::make_unique<SmallRing>();
  CHECK_THROWS_WITH_AS(validateAttentionRing(ring.get(), sizeof(SmallRing) - 64, "cut"),
                       doctest::Contains("cut: region is"), std::runtime_error);

  CHECK(attentionShmName("nao_attn") == "/nao_attn");
  CHECK(attentionShmName("/nao_attn") == "/nao_attn");
  CHECK_THROWS_WITH_AS(attentionShmName("a/b"), doctest::Contains("holds a '/'"), std::runtime_error);
  CHECK_THROWS_AS(attentionShmName(""), std::runtime_error);
}
