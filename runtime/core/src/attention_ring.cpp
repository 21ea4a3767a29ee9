// The attention ring's in-process part (nao/attention_ring.hpp): status names and the check of a
// ring region's header.
#include "nao/attention_ring.hpp"

#include <cstdio>

namespace nao {

static_assert(offsetof(AttentionRingHeader, magic) == 0 && offsetof(AttentionRingHeader, layout_version) == 8 &&
                  offsetof(AttentionRingHeader, header_bytes) == 12 && offsetof(AttentionRingHeader, capacity) == 16 &&
                  offsetof(AttentionRingHeader, payload_bytes) == 24 &&
                  offsetof(AttentionRingHeader, payload_offset) == 32 && offsetof(AttentionRingHeader, slot_bytes) == 40 &&
                  offsetof(AttentionRingHeader, total_bytes) == 48 && offsetof(AttentionRingHeader, descriptor) == 56 &&
                  offsetof(AttentionRingHeader, n_written) == 128 && offsetof(AttentionRingHeader, closed) == 136 &&
                  offsetof(AttentionRingHeader, writer_next) == 192 && sizeof(AttentionRingHeader) == 256,
              "ring header layout documented in docs/attention_bin.md");

namespace {

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw std::runtime_error(origin + ": " + what);
}

std::string hex64(std::uint64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

bool isPowerOfTwo(std::uint64_t v) { return v != 0 && (v & (v - 1)) == 0; }

}  // namespace

const char* attentionReadName(AttentionRead status) {
  switch (status) {
    case AttentionRead::kOk: return "ok";
    case AttentionRead::kNotYetWritten: return "not yet written";
    case AttentionRead::kOverwritten: return "overwritten";
    case AttentionRead::kTorn: return "torn";
  }
  return "unknown";
}

AttentionRingView validateAttentionRing(const void* bytes, std::size_t region_bytes, const std::string& origin) {
  if (region_bytes < sizeof(AttentionRingHeader))
    fail(origin, "region of " + std::to_string(region_bytes) + " bytes is smaller than an attention ring header (" +
                     std::to_string(sizeof(AttentionRingHeader)) + " bytes): not a nao-rt attention ring");
  const auto* h = std::launder(static_cast<const AttentionRingHeader*>(bytes));
  // Acquire: pairs with the constructor's release, so the fields below are complete.
  const std::uint64_t magic = h->magic.load(std::memory_order_acquire);
  if (magic != kAttentionRingMagic)
    fail(origin, "not a nao-rt attention ring (magic " + hex64(magic) + ", expected " + hex64(kAttentionRingMagic) +
                     " \"NAORING1\"; or its writer is still creating it)");
  if (h->layout_version != kAttentionRingLayoutVersion)
    fail(origin, "ring layout version " + std::to_string(h->layout_version) + ", this program reads version " +
                     std::to_string(kAttentionRingLayoutVersion));
  auto bad = [&](const std::string& what) { fail(origin, "corrupt ring header: " + what); };
  if (h->header_bytes < sizeof(AttentionRingHeader) || h->header_bytes % kCacheLineBytes != 0)
    bad("header size " + std::to_string(h->header_bytes));
  if (!isPowerOfTwo(h->capacity) || h->capacity > (std::uint64_t{1} << 32))
    bad("capacity " + std::to_string(h->capacity) + " is not a power of two up to 2^32");
  if (h->slot_bytes == 0 || h->slot_bytes % kCacheLineBytes != 0 || h->slot_bytes > (std::uint64_t{1} << 32))
    bad("slot size " + std::to_string(h->slot_bytes));
  if (h->payload_offset < sizeof(std::uint64_t) || h->payload_bytes == 0 ||
      h->payload_offset + h->payload_bytes > h->slot_bytes)
    bad("payload of " + std::to_string(h->payload_bytes) + " bytes at offset " + std::to_string(h->payload_offset) +
        " does not fit a slot of " + std::to_string(h->slot_bytes) + " bytes");
  // Both factors are capped at 2^32 above: the product cannot overflow.
  const std::uint64_t total = h->header_bytes + h->capacity * h->slot_bytes;
  if (h->total_bytes != total)
    bad("total size " + std::to_string(h->total_bytes) + " != header + capacity x slot = " + std::to_string(total));
  if (total > region_bytes)
    fail(origin, "region is " + std::to_string(region_bytes) + " bytes, its header describes a ring of " +
                     std::to_string(total) + " bytes");
  return {h, static_cast<const unsigned char*>(bytes) + h->header_bytes};
}

}  // namespace nao
