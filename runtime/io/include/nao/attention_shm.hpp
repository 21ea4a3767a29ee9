// The attention ring (nao/attention_ring.hpp) outside the process: in POSIX shared memory, where
// another process reads it live (nao_attn_tail), and dumped to attention.bin at the end of a run.
// Configure time and end of run: these allocate, do I/O and throw.
#pragma once

#include "nao/attention_ring.hpp"

#include <cstddef>
#include <cstdint>
#include <new>
#include <stdexcept>
#include <string>

namespace nao {

// Shared memory (configure time; these allocate and throw).

/// The POSIX shared-memory name for `name`: a leading '/' is prepended if missing ("nao_attn"
/// -> "/nao_attn", which Linux shows as /dev/shm/nao_attn). Throws std::runtime_error if the
/// name is empty, holds another '/', or is longer than 255 characters.
std::string attentionShmName(const std::string& name);

/// A POSIX shared-memory mapping holding a ring (RAII). The creator (the writer's process, at
/// configure time) makes and later unlinks the name; a reader maps it read-only, so it cannot
/// write anything into the writer's memory. Move-only.
class AttentionShm {
 public:
  /// Writer side: unlinks a stale region of the same name, creates it (O_CREAT | O_EXCL, mode
  /// 0644), sizes it to `bytes`, maps it read-write and, if `try_mlock`, tries to lock it in
  /// RAM (locked() says whether that worked; failure is not an error). The region is zero;
  /// placement-construct the ring in it (SharedAttentionRing does). Unlinked on destruction.
  /// Throws std::runtime_error naming the region and the failing call.
  static AttentionShm create(const std::string& name, std::size_t bytes, bool try_mlock);
  /// Reader side: opens an existing region O_RDONLY, maps it PROT_READ, and validates the ring
  /// header (validateAttentionRing). Throws std::runtime_error naming the region and the
  /// problem (does not exist, too small, not a nao-rt attention ring, wrong version or sizes).
  static AttentionShm openReadOnly(const std::string& name);

  AttentionShm(AttentionShm&& other) noexcept;
  AttentionShm& operator=(AttentionShm&& other) noexcept;
  AttentionShm(const AttentionShm&) = delete;
  AttentionShm& operator=(const AttentionShm&) = delete;
  ~AttentionShm();

  const std::string& name() const { return name_; }
  std::size_t size() const { return size_; }
  bool isCreator() const { return creator_; }
  bool locked() const { return locked_; }
  const void* data() const { return data_; }
  /// The mapping, writable: creator only (nullptr for a reader).
  void* writableData() { return creator_ ? data_ : nullptr; }
  /// View of the ring in the mapping (reader: validated at open; creator: once constructed).
  AttentionRingView view() const;

 private:
  AttentionShm() = default;
  void release() noexcept;

  std::string name_;
  void* data_ = nullptr;
  std::size_t size_ = 0;
  bool creator_ = false;
  bool locked_ = false;
};

/// The ring of type Ring inside a read-only mapping, after checking that its capacity, payload
/// size and slot layout are Ring's. Throws std::runtime_error naming the region and the
/// mismatch. Use it with the typed readFromNonRT (loads only: fine on a PROT_READ mapping).
template <typename Ring>
const Ring& attachAttentionRing(const AttentionShm& shm) {
  const AttentionRingHeader& h = *shm.view().header;
  auto mismatch = [&](const char* what, std::uint64_t have, std::uint64_t want) {
    throw std::runtime_error("attention ring " + shm.name() + ": " + what + " is " + std::to_string(have) +
                             ", this program expects " + std::to_string(want));
  };
  if (h.capacity != Ring::kCapacity) mismatch("capacity", h.capacity, Ring::kCapacity);
  if (h.payload_bytes != sizeof(typename Ring::payload_type))
    mismatch("payload size", h.payload_bytes, sizeof(typename Ring::payload_type));
  if (h.slot_bytes != sizeof(typename Ring::Slot)) mismatch("slot size", h.slot_bytes, sizeof(typename Ring::Slot));
  if (h.header_bytes != offsetof(Ring, slots)) mismatch("header size", h.header_bytes, offsetof(Ring, slots));
  if (h.total_bytes != sizeof(Ring)) mismatch("ring size", h.total_bytes, sizeof(Ring));
  return *std::launder(reinterpret_cast<const Ring*>(shm.data()));
}

/// The writer's ring in shared memory: creates the region (AttentionShm::create), constructs
/// the ring in it; on destruction closes the ring (readers see closed), unmaps and unlinks.
/// Configure time. Neither copyable nor movable (readers' pointers stay valid): hold it in a
/// std::optional or std::unique_ptr.
template <typename Ring>
class SharedAttentionRing {
 public:
  SharedAttentionRing(const std::string& name, const AttentionDescriptor& descriptor, bool try_mlock = true)
      : shm_(AttentionShm::create(name, sizeof(Ring), try_mlock)), ring_(new (shm_.writableData()) Ring(descriptor)) {}
  SharedAttentionRing(const SharedAttentionRing&) = delete;
  SharedAttentionRing& operator=(const SharedAttentionRing&) = delete;
  ~SharedAttentionRing() {
    closeFromRT(*ring_);
    ring_->~Ring();
  }

  Ring& ring() { return *ring_; }
  const Ring& ring() const { return *ring_; }
  const AttentionShm& shm() const { return shm_; }

 private:
  AttentionShm shm_;
  Ring* ring_;
};

// ---------------------------------------------------------------------------------------------
// attention.bin (end of run; allocates, does I/O, throws).

inline constexpr char kAttentionFileMagic[8] = {'N', 'A', 'O', 'A', 'T', 'T', 'N', '1'};
inline constexpr std::uint32_t kAttentionFileVersion = 1;
inline constexpr std::uint32_t kAttentionFileHeaderBytes = 96;

/// What writeAttentionFile wrote.
struct AttentionFileSummary {
  std::uint64_t first_record = 0;    ///< number of the first record in the file
  std::uint64_t record_count = 0;    ///< records in the file
  std::uint64_t records_written = 0; ///< records the ring had received when the dump began
};

/// Writes `path` (docs/attention_bin.md): the 96-byte little-endian header, then the records
/// still in the ring, oldest first, each payload_bytes as stored. Meant for the end of a run
/// (writer stopped); if the writer is still pushing, records it overwrites during the dump are
/// dropped from the front so the file stays contiguous. Written to a temporary file and renamed
/// into place. Deterministic: the same pushes give a byte-identical file. Any non-RT thread.
/// Throws std::runtime_error naming the file on I/O errors or a torn record.
AttentionFileSummary writeAttentionFile(const std::string& path, const AttentionRingView& view);

template <typename Payload, std::size_t Capacity>
AttentionFileSummary writeAttentionFile(const std::string& path, const AttentionRing<Payload, Capacity>& ring) {
  return writeAttentionFile(path, attentionRingView(ring));
}

}  // namespace nao
