// The attention ring buffer: the last Capacity attention records of the controller,
// written by one thread (the control thread) and read by any number of readers, in this process
// or in another one through POSIX shared memory, without ever blocking or slowing the writer.
//
// Layout: one standard-layout block, the same in process memory and in a shared-memory mapping:
//   AttentionRingHeader   magic, layout version, capacity, payload/slot sizes, the caller's
//                         layout descriptor (8 u32), the count of records written
//   Slot[Capacity]        each cache-line aligned: atomic u64 sequence, then the payload
// Record r (numbered from 0 in push order) lives in slot r mod Capacity until record
// r + Capacity replaces it.
//
// Per-slot seqlock. The slot's sequence is 0 (never written), 2r+1 (record r being written) or
// 2r+2 (record r complete). The writer marks the slot odd, copies the payload, marks it even,
// then publishes the count; it never waits for anyone (wait-free, no allocation, no syscall).
// A reader loads the sequence, copies the payload, and loads the sequence again: equal and
// equal to 2r+2 means the copy is record r, intact; anything else means the writer was in the
// slot meanwhile, and the copy is thrown away. Readers only load: a read-only mapping suffices.
//
// The standard seqlock caveat: the payload copy is a plain memcpy racing with the writer's
// memcpy, which the C++ memory model calls a data race even though a torn copy is detected and
// discarded (Boehm, "Can seqlocks get along with programming language memory models?", 2012).
// This is the accepted practice (Linux kernel seqlocks, folly, realtime rings): on x86-64 with
// GCC/Clang the copy compiles to ordinary loads and stores, the acquire fence placed before
// the second sequence load keeps those loads from moving past it, and the value of a torn copy
// is never used. A payload must therefore be trivially copyable and must not be read field by
// field in place: copy it out with readFromNonRT first.
//
// Thread names say the side: *FromRT functions are for the one writer thread and are real-time
// safe; *FromNonRT functions are for readers and never block the writer. The rest
// (recordsWritten, latestRecord, ...) are safe on any thread.
#pragma once

#include "nao/arm_model.hpp"

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace nao {

inline constexpr std::size_t kCacheLineBytes = 64;
/// Default ring capacity: 1024 records = 102.4 s of 10 Hz ticks.
inline constexpr std::size_t kDefaultAttentionCapacity = 1024;
/// Number of u32 fields of the caller's layout descriptor stored in the ring header.
inline constexpr int kAttentionDescriptorFields = 8;
/// How many times readFromNonRT re-reads a slot whose sequence shows a write of the wanted
/// record in progress before it reports kTorn.
inline constexpr int kAttentionReadAttempts = 16;

/// "NAORING1" read as a little-endian u64: the first 8 bytes of every ring block.
inline constexpr std::uint64_t kAttentionRingMagic = 0x31474E49524F414Eull;
inline constexpr std::uint32_t kAttentionRingLayoutVersion = 1;

/// Caller-defined u32 fields describing the payload, so that a reader that does not know the
/// payload type at compile time can interpret it (AttentionPayload uses the first five, see
/// attentionPayloadDescriptor). Unused fields are 0.
using AttentionDescriptor = std::array<std::uint32_t, kAttentionDescriptorFields>;

// Shared memory holds these atomics and other processes map them: they must be plain lock-free
// words, not a lock hidden in a library (address-free, docs/attention_bin.md).
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "the ring needs lock-free 64-bit atomics");
static_assert(sizeof(std::atomic<std::uint64_t>) == 8, "the ring layout assumes 8-byte atomics");

/// The ring's header: the first kCacheLineBytes-aligned part of the block. Every field but
/// n_written, closed and writer_next is written once, before the magic is published (release).
/// Byte offsets (docs/attention_bin.md): magic 0, layout_version 8, header_bytes 12, capacity 16,
/// payload_bytes 24, payload_offset 32, slot_bytes 40, total_bytes 48, descriptor 56,
/// n_written 128, closed 136, writer_next 192; size 256.
struct alignas(kCacheLineBytes) AttentionRingHeader {
  std::atomic<std::uint64_t> magic{0};  ///< kAttentionRingMagic once the block is fully built
  std::uint32_t layout_version = 0;     ///< kAttentionRingLayoutVersion
  std::uint32_t header_bytes = 0;       ///< offset of slot 0 from the start of the block
  std::uint64_t capacity = 0;           ///< slots, a power of two
  std::uint64_t payload_bytes = 0;      ///< sizeof(Payload)
  std::uint64_t payload_offset = 0;     ///< offset of the payload inside a slot
  std::uint64_t slot_bytes = 0;         ///< slot stride, a multiple of kCacheLineBytes
  std::uint64_t total_bytes = 0;        ///< header_bytes + capacity * slot_bytes
  std::uint32_t descriptor[kAttentionDescriptorFields] = {};  ///< the caller's layout descriptor
  /// Records pushed so far = the number of the next record. Its own cache line: the writer
  /// stores it every push, readers poll it, and neither should drag the constant fields along.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> n_written{0};
  std::atomic<std::uint64_t> closed{0};  ///< 1: the writer will push no more records
  /// The writer's own copy of n_written, on a line readers never touch: loading n_written
  /// itself would miss in cache every push while a reader polls it (measured: back-to-back
  /// pushes ~35 % slower with a hammering reader). Writer thread only; meaningless to readers.
  alignas(kCacheLineBytes) std::uint64_t writer_next = 0;
};

/// The ring: header, then Capacity slots. Build it once at configure time (it is large: use
/// std::make_unique, or SharedAttentionRing for shared memory); the constructor zeroes every
/// slot, which also faults its pages in before the loop runs.
/// @tparam Payload  one record; trivially copyable (it is copied byte-wise under the seqlock)
/// @tparam Capacity records kept; a power of two (record r is in slot r & (Capacity - 1))
template <typename Payload, std::size_t Capacity = kDefaultAttentionCapacity>
struct AttentionRing {
  static_assert(std::is_trivially_copyable_v<Payload>, "ring payloads are copied byte-wise: trivially copyable only");
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0, "ring capacity must be a power of two");

  using payload_type = Payload;
  static constexpr std::size_t kCapacity = Capacity;

  struct alignas(kCacheLineBytes) Slot {
    std::atomic<std::uint64_t> seq{0};  ///< 0 never written, 2r+1 writing record r, 2r+2 holds record r
    Payload payload{};
  };

  AttentionRingHeader header;
  Slot slots[Capacity];

  explicit AttentionRing(const AttentionDescriptor& descriptor = {});
  AttentionRing(const AttentionRing&) = delete;
  AttentionRing& operator=(const AttentionRing&) = delete;
};

/// Outcome of one read.
enum class AttentionRead : std::uint32_t {
  kOk = 0,             ///< `out` holds the record, intact
  kNotYetWritten = 1,  ///< the record has not been (completely) pushed yet
  kOverwritten = 2,    ///< the record was replaced by record + capacity (the reader fell behind)
  kTorn = 3,           ///< the slot showed this record half-written on every attempt: a writer
                       ///< that stopped mid-write (crashed) or corrupt memory; never seen otherwise
};

const char* attentionReadName(AttentionRead status);

/// A type-erased, read-only look at a ring: what a reader that does not know Payload and
/// Capacity at compile time (nao_attn_tail, the file dump) works with. Points into the ring's
/// memory; valid as long as the ring (or its mapping) lives.
struct AttentionRingView {
  const AttentionRingHeader* header = nullptr;
  const unsigned char* slots = nullptr;  ///< slot 0 (= block start + header_bytes)
};

namespace detail {

// The reader half of the seqlock, shared by the typed and the type-erased readers. It decides
// from the slot's sequence alone and loads the shared count only in the one ambiguous case: a
// reader should add as little traffic as possible to the lines the writer stores every push.
inline AttentionRead readSlot(const AttentionRingHeader& header, const std::atomic<std::uint64_t>& seq,
                              const void* payload, std::size_t payload_bytes, std::uint64_t record, void* out) {
  const std::uint64_t complete = 2 * record + 2;
  for (int attempt = 0; attempt < kAttentionReadAttempts; ++attempt) {
    const std::uint64_t s1 = seq.load(std::memory_order_acquire);
    if (s1 > complete) return AttentionRead::kOverwritten;  // writing or holding record + k*capacity
    if (s1 + 1 < complete) return AttentionRead::kNotYetWritten;  // the slot still holds an older record
    if (s1 + 1 == complete) {
      // Record half-written: being pushed right now (not yet published), or, if already counted,
      // a copy that has to be tried again.
      if (header.n_written.load(std::memory_order_acquire) <= record) return AttentionRead::kNotYetWritten;
      continue;
    }
    std::memcpy(out, payload, payload_bytes);
    // Keeps the copy's loads before the second sequence load (the seqlock caveat, top of file).
    std::atomic_thread_fence(std::memory_order_acquire);
    const std::uint64_t s2 = seq.load(std::memory_order_relaxed);
    if (s2 == s1) return AttentionRead::kOk;
    if (s2 > complete) return AttentionRead::kOverwritten;
  }
  return AttentionRead::kTorn;
}

inline const std::atomic<std::uint64_t>& slotSequence(const AttentionRingView& view, std::uint64_t record) {
  const unsigned char* slot = view.slots + (record & (view.header->capacity - 1)) * view.header->slot_bytes;
  return *std::launder(reinterpret_cast<const std::atomic<std::uint64_t>*>(slot));
}

}  // namespace detail

template <typename Payload, std::size_t Capacity>
AttentionRing<Payload, Capacity>::AttentionRing(const AttentionDescriptor& descriptor) {
  static_assert(std::is_standard_layout_v<AttentionRing>, "the ring block must be standard-layout");
  static_assert(offsetof(Slot, seq) == 0, "a slot starts with its sequence");
  header.layout_version = kAttentionRingLayoutVersion;
  header.header_bytes = static_cast<std::uint32_t>(offsetof(AttentionRing, slots));
  header.capacity = Capacity;
  header.payload_bytes = sizeof(Payload);
  header.payload_offset = offsetof(Slot, payload);
  header.slot_bytes = sizeof(Slot);
  header.total_bytes = sizeof(AttentionRing);
  for (int i = 0; i < kAttentionDescriptorFields; ++i) header.descriptor[i] = descriptor[static_cast<std::size_t>(i)];
  // Published last: a reader that sees the magic sees every field above.
  header.magic.store(kAttentionRingMagic, std::memory_order_release);
}

/// Appends one record. Writer thread only (one writer per ring). Wait-free: a fixed number of
/// stores and one memcpy of sizeof(Payload); no allocation, no lock, no syscall. Real-time safe.
/// @return the record's number (0 for the first push)
template <typename Payload, std::size_t Capacity>
std::uint64_t pushFromRT(AttentionRing<Payload, Capacity>& ring, const Payload& payload) noexcept {
  // Single writer: its private count, not the shared one readers poll (see writer_next).
  const std::uint64_t record = ring.header.writer_next;
  auto& slot = ring.slots[record & (Capacity - 1)];
  slot.seq.store(2 * record + 1, std::memory_order_relaxed);
  // Orders the odd mark before the payload stores: a reader that copied any new byte then
  // sees the odd (or a later) sequence on its second load.
  std::atomic_thread_fence(std::memory_order_release);
  std::memcpy(&slot.payload, &payload, sizeof(Payload));
  slot.seq.store(2 * record + 2, std::memory_order_release);
  ring.header.n_written.store(record + 1, std::memory_order_release);
  ring.header.writer_next = record + 1;
  return record;
}

/// Marks the ring finished: readers (nao_attn_tail) stop after the last record. Writer thread
/// (after its last push). Real-time safe.
template <typename Payload, std::size_t Capacity>
void closeFromRT(AttentionRing<Payload, Capacity>& ring) noexcept {
  ring.header.closed.store(1, std::memory_order_release);
}

/// Copies record `record` into `out` if it is still in the ring. Reader threads; never blocks
/// or slows the writer (only loads from the ring), allocation-free, bounded (at most
/// kAttentionReadAttempts copies). `out` is written even when the status is not kOk: use it
/// only on kOk.
template <typename Payload, std::size_t Capacity>
AttentionRead readFromNonRT(const AttentionRing<Payload, Capacity>& ring, std::uint64_t record, Payload& out) {
  const auto& slot = ring.slots[record & (Capacity - 1)];
  return detail::readSlot(ring.header, slot.seq, &slot.payload, sizeof(Payload), record, &out);
}

/// Type-erased read: copies view.header->payload_bytes bytes into `out`. Same contract as the
/// typed readFromNonRT.
inline AttentionRead readFromNonRT(const AttentionRingView& view, std::uint64_t record, void* out) {
  const AttentionRingHeader& h = *view.header;
  const unsigned char* slot = view.slots + (record & (h.capacity - 1)) * h.slot_bytes;
  return detail::readSlot(h, detail::slotSequence(view, record), slot + h.payload_offset, h.payload_bytes, record, out);
}

/// Records pushed so far (= the number of the next record). Any thread.
inline std::uint64_t recordsWritten(const AttentionRingHeader& header) {
  return header.n_written.load(std::memory_order_acquire);
}
/// Number of the newest record, or nothing before the first push. Any thread.
inline std::optional<std::uint64_t> latestRecord(const AttentionRingHeader& header) {
  const std::uint64_t n = recordsWritten(header);
  if (n == 0) return std::nullopt;
  return n - 1;
}
/// Number of the oldest record still in the ring (0 before the first Capacity pushes). Any thread.
inline std::uint64_t oldestRecord(const AttentionRingHeader& header) {
  const std::uint64_t n = recordsWritten(header);
  return n > header.capacity ? n - header.capacity : 0;
}
/// True once the writer called closeFromRT. Any thread.
inline bool isClosed(const AttentionRingHeader& header) { return header.closed.load(std::memory_order_acquire) != 0; }

template <typename Payload, std::size_t Capacity>
std::uint64_t recordsWritten(const AttentionRing<Payload, Capacity>& ring) { return recordsWritten(ring.header); }
template <typename Payload, std::size_t Capacity>
std::optional<std::uint64_t> latestRecord(const AttentionRing<Payload, Capacity>& ring) { return latestRecord(ring.header); }
template <typename Payload, std::size_t Capacity>
std::uint64_t oldestRecord(const AttentionRing<Payload, Capacity>& ring) { return oldestRecord(ring.header); }

template <typename Payload, std::size_t Capacity>
AttentionRingView attentionRingView(const AttentionRing<Payload, Capacity>& ring) {
  return {&ring.header, reinterpret_cast<const unsigned char*>(&ring.slots[0])};
}

// ---------------------------------------------------------------------------------------------
// The controller's payload.

/// Value of descriptor[0] for AttentionPayload version 2 (docs/attention_bin.md; version 1 had no
/// mass and no temporal profile: the single-instant policy).
inline constexpr std::uint32_t kAttentionPayloadFormat = 2;
/// Byte offsets every AttentionPayload shares, whatever L, H, D, W (what nao_attn_tail relies on).
inline constexpr std::size_t kAttentionPayloadTickOffset = 0;
inline constexpr std::size_t kAttentionPayloadFaultOffset = 8;
inline constexpr std::size_t kAttentionPayloadScoreOffset = 16;

/// One tick's attention record as the controller pushes it (docs/policy.md "Attention record";
/// byte layout in docs/attention_bin.md). Fixed layout, little-endian floats and integers.
/// @tparam L decoder layers, H heads, D d_model, W window (ticks); tokens = body parts = kNumJoints.
template <int L, int H, int D, int W>
struct AttentionPayload {
  static_assert(L >= 1 && H >= 1 && D >= 1 && W >= 1, "attention payload dimensions must be positive");
  static constexpr int kLayers = L;
  static constexpr int kHeads = H;
  static constexpr int kDModel = D;
  static constexpr int kWindow = W;
  static constexpr int kTokens = kNumJoints;

  std::uint64_t tick = 0;      ///< controller tick index
  std::uint32_t fault = 0;     ///< the tick's fault bits (0 = none)
  std::uint32_t reserved = 0;  ///< 0
  float score[kTokens] = {};   ///< per-body-part norm-based score, last decoder layer, summed over the window
  float mass[kTokens] = {};    ///< per-body-part raw cross-attention mass, last decoder layer (sums to 1)
  float age_profile[W] = {};   ///< last decoder layer's attention mass per age, 0 = this tick (sums to 1)
  float cross[L][H][kTokens][kTokens] = {};  ///< cross-attention α[l][h][action token i][body part j], summed over the window
  float cross_out[kTokens][D] = {};          ///< last decoder layer's cross-attention output per action token
  // 0 or 4 bytes of padding here (zeroed by sealPayload) so that checksum is 8-byte aligned.
  std::uint64_t checksum = 0;  ///< FNV-1a 64 of every byte before this field (sealPayload)
};

/// The descriptor a ring of AttentionPayload<L, H, D, W> carries: {format, L, H, tokens, D, W, 0, 0}.
template <typename Payload>
constexpr AttentionDescriptor attentionPayloadDescriptor() {
  return {kAttentionPayloadFormat, static_cast<std::uint32_t>(Payload::kLayers),
          static_cast<std::uint32_t>(Payload::kHeads), static_cast<std::uint32_t>(Payload::kTokens),
          static_cast<std::uint32_t>(Payload::kDModel), static_cast<std::uint32_t>(Payload::kWindow), 0, 0};
}

/// FNV-1a 64 over `size` bytes (the payload checksum; same function as model.bin's).
inline std::uint64_t attentionFnv1a64(const void* data, std::size_t size) {
  const auto* p = static_cast<const unsigned char*>(data);
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (std::size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

/// Checksum of a payload: FNV-1a 64 of its bytes before `checksum`. Real-time safe.
template <int L, int H, int D, int W>
std::uint64_t payloadChecksum(const AttentionPayload<L, H, D, W>& payload) {
  using P = AttentionPayload<L, H, D, W>;
  static_assert(std::is_standard_layout_v<P> && std::is_trivially_copyable_v<P>);
  static_assert(offsetof(P, tick) == kAttentionPayloadTickOffset && offsetof(P, fault) == kAttentionPayloadFaultOffset &&
                offsetof(P, score) == kAttentionPayloadScoreOffset, "fixed part of the payload layout");
  static_assert(offsetof(P, checksum) + sizeof(std::uint64_t) == sizeof(P), "checksum is the last 8 bytes");
  return attentionFnv1a64(&payload, offsetof(P, checksum));
}

/// Zeroes the padding before `checksum` (so equal payloads have equal bytes: determinism of
/// attention.bin) and sets `checksum`. Call after filling the payload, before pushFromRT.
/// Real-time safe.
template <int L, int H, int D, int W>
void sealPayload(AttentionPayload<L, H, D, W>& payload) {
  using P = AttentionPayload<L, H, D, W>;
  constexpr std::size_t data_end = offsetof(P, cross_out) + sizeof(payload.cross_out);
  constexpr std::size_t pad = offsetof(P, checksum) - data_end;
  if constexpr (pad > 0) std::memset(reinterpret_cast<unsigned char*>(&payload) + data_end, 0, pad);
  payload.checksum = payloadChecksum(payload);
}

/// True if the payload's checksum matches its bytes. Any thread.
template <int L, int H, int D, int W>
bool payloadIntact(const AttentionPayload<L, H, D, W>& payload) {
  return payload.checksum == payloadChecksum(payload);
}

// ---------------------------------------------------------------------------------------------
/// Checks that `bytes` (a region of `region_bytes`) hold a complete ring of this layout version;
/// throws std::runtime_error "<origin>: <problem>" otherwise. Returns a view into it.
AttentionRingView validateAttentionRing(const void* bytes, std::size_t region_bytes, const std::string& origin);

}  // namespace nao
