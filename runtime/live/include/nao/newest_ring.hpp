// The newest value of a producer thread, handed to a real-time consumer without a lock: the
// live camera's reader thread publishes each skeleton, the control thread takes the newest.
//
// A ring of Slots seqlocked slots, like the attention ring (attention_ring.hpp) but turned the
// other way round: here the writer is the helper thread and the reader is the real-time one,
// and only the newest value matters. The writer fills slot (n mod Slots) under its sequence
// (odd while writing, even when complete) and then publishes n as the newest. The reader loads
// the newest number, copies that slot and checks the slot's sequence before and after: the copy
// is torn only if the writer came round the whole ring (Slots more publications) during one
// copy, which at camera rates never happens; a torn copy is detected and retried a bounded
// number of times. Neither side ever waits for the other, allocates or makes a system call.
// The seqlock caveat of attention_ring.hpp applies (a racing memcpy of a trivially copyable
// payload, discarded when torn).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace nao {

template <typename T, std::size_t Slots = 4>
struct NewestRing {
  static_assert(std::is_trivially_copyable_v<T>, "ring values are copied byte-wise: trivially copyable only");
  static_assert(Slots >= 2 && (Slots & (Slots - 1)) == 0, "slot count must be a power of two");

  struct alignas(64) Slot {
    std::atomic<std::uint64_t> seq{0};  ///< 0 never written, 2n-1 writing value n, 2n holds value n
    T value{};
  };
  alignas(64) std::atomic<std::uint64_t> newest{0};  ///< number of the newest complete value (0: none)
  std::uint64_t writer_next = 1;                     ///< writer thread only
  Slot slots[Slots];
};

/// Publishes `value` as the newest (numbered 1, 2, ...). One writer thread. Wait-free,
/// allocation-free. Returns its number.
template <typename T, std::size_t Slots>
std::uint64_t publishNewest(NewestRing<T, Slots>& ring, const T& value) noexcept {
  const std::uint64_t n = ring.writer_next++;
  auto& slot = ring.slots[n & (Slots - 1)];
  slot.seq.store(2 * n - 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);  // the odd mark before the value's bytes
  std::memcpy(&slot.value, &value, sizeof(T));
  slot.seq.store(2 * n, std::memory_order_release);
  ring.newest.store(n, std::memory_order_release);
  return n;
}

/// How many times readNewest retries a copy torn by the writer before it gives up.
inline constexpr int kNewestReadAttempts = 8;

/// Copies the newest value into `out` and returns its number; 0 when nothing was published yet
/// or every attempt was torn (then `out` is unspecified). Any number of reader threads; never
/// blocks or slows the writer; real-time safe.
template <typename T, std::size_t Slots>
std::uint64_t readNewest(const NewestRing<T, Slots>& ring, T& out) noexcept {
  for (int attempt = 0; attempt < kNewestReadAttempts; ++attempt) {
    const std::uint64_t n = ring.newest.load(std::memory_order_acquire);
    if (n == 0) return 0;
    const auto& slot = ring.slots[n & (Slots - 1)];
    const std::uint64_t s1 = slot.seq.load(std::memory_order_acquire);
    if (s1 != 2 * n) continue;  // already being replaced by n + Slots: take the newer one
    std::memcpy(&out, &slot.value, sizeof(T));
    std::atomic_thread_fence(std::memory_order_acquire);  // the copy's loads before the re-check
    if (slot.seq.load(std::memory_order_relaxed) == s1) return n;
  }
  return 0;
}

}  // namespace nao
