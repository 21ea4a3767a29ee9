// nao_attn_tail: prints the per-body-part attention scores of a running controller live, one
// line per tick, from its shared-memory attention ring (nao_rt --attention-shm NAME).
//
// Reads only: the ring is mapped read-only, so the controller cannot be disturbed. The payload's
// L, H and d_model are not compiled in: the ring header's descriptor says which payload format
// it is, and the fields printed (tick, fault, score[5]) sit at fixed offsets at its start
// (docs/attention_bin.md).
#include "nao/arm_model.hpp"
#include "nao/attention_shm.hpp"
#include "nao/attention_ring.hpp"

#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include <time.h>

namespace {

volatile std::sig_atomic_t g_stop = 0;

extern "C" void onSignal(int) { g_stop = 1; }

void sleepMs(int ms) {
  timespec ts{};
  ts.tv_sec = ms / 1000;
  ts.tv_nsec = static_cast<long>(ms % 1000) * 1000000L;
  ::nanosleep(&ts, nullptr);  // a signal cuts it short: fine, the loop checks g_stop
}

template <typename T>
T load(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Print the per-body-part attention scores of a running nao_rt, one line per tick, "
               "from its shared-memory attention ring (nao_rt --attention-shm NAME)."};
  std::string name;
  std::uint64_t count = 0;
  int interval_ms = 20;
  bool from_oldest = false;
  app.add_option("NAME", name, "shared-memory name of the ring (a leading '/' is added if missing)")->required();
  app.add_option("--count", count, "exit after printing this many records (0: until the writer closes the ring or Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--interval-ms", interval_ms, "polling period when no new record is there, ms")
      ->check(CLI::Range(1, 60000));
  app.add_flag("--from-oldest", from_oldest, "start with the oldest record still in the ring, not the newest");
  CLI11_PARSE(app, argc, argv);

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  nao::AttentionShm shm = [&] {
    try {
      return nao::AttentionShm::openReadOnly(name);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "nao_attn_tail: %s\n", e.what());
      std::exit(1);
    }
  }();
  const nao::AttentionRingView view = shm.view();
  const nao::AttentionRingHeader& h = *view.header;
  // Only the fixed start of the payload is read; the rest (L, H, d_model) may be anything.
  constexpr std::size_t kFixedBytes = nao::kAttentionPayloadScoreOffset + sizeof(float) * nao::kNumJoints;
  if (h.descriptor[0] != nao::kAttentionPayloadFormat || h.descriptor[3] != static_cast<std::uint32_t>(nao::kNumJoints) ||
      h.payload_bytes < kFixedBytes + sizeof(std::uint64_t)) {
    std::fprintf(stderr,
                 "nao_attn_tail: attention ring %s: payload format %u with %u tokens and %llu bytes; this tool reads "
                 "format %u with %d tokens\n",
                 shm.name().c_str(), h.descriptor[0], h.descriptor[3], static_cast<unsigned long long>(h.payload_bytes),
                 nao::kAttentionPayloadFormat, nao::kNumJoints);
    return 1;
  }
  std::fprintf(stderr, "# %s: capacity %llu, payload %llu bytes, decoder layers %u, heads %u, d_model %u\n",
               shm.name().c_str(), static_cast<unsigned long long>(h.capacity),
               static_cast<unsigned long long>(h.payload_bytes), h.descriptor[1], h.descriptor[2], h.descriptor[4]);

  std::printf("%10s %8s", "tick", "fault");
  for (const char* joint : nao::kJointNames) std::printf(" %14s", joint);
  std::printf("\n");
  std::fflush(stdout);

  std::vector<unsigned char> payload(h.payload_bytes);
  const std::size_t checksum_offset = payload.size() - sizeof(std::uint64_t);
  std::uint64_t next = 0;
  bool started = false;
  std::uint64_t printed = 0;
  while (!g_stop && (count == 0 || printed < count)) {
    const bool closed = nao::isClosed(h);  // before the count: records pushed before closing are seen
    const std::uint64_t n = nao::recordsWritten(h);
    if (!started && n > 0) {
      next = from_oldest ? nao::oldestRecord(h) : n - 1;
      started = true;
    }
    if (!started || next >= n) {
      if (closed) {
        std::fprintf(stderr, "# the writer closed the ring after %llu records\n", static_cast<unsigned long long>(n));
        break;
      }
      sleepMs(interval_ms);
      continue;
    }
    switch (nao::readFromNonRT(view, next, payload.data())) {
      case nao::AttentionRead::kOk: {
        const unsigned char* p = payload.data();
        const bool intact = nao::attentionFnv1a64(p, checksum_offset) == load<std::uint64_t>(p + checksum_offset);
        std::printf("%10llu %8u",
                    static_cast<unsigned long long>(load<std::uint64_t>(p + nao::kAttentionPayloadTickOffset)),
                    load<std::uint32_t>(p + nao::kAttentionPayloadFaultOffset));
        for (int j = 0; j < nao::kNumJoints; ++j)
          std::printf(" %14.6f", static_cast<double>(load<float>(p + nao::kAttentionPayloadScoreOffset + sizeof(float) * j)));
        std::printf(intact ? "\n" : "  BAD-CHECKSUM\n");
        std::fflush(stdout);
        ++printed;
        ++next;
        break;
      }
      case nao::AttentionRead::kOverwritten: {
        // Fell behind by more than the ring holds: say how many, go on with the oldest left.
        const std::uint64_t oldest = nao::oldestRecord(h);
        const std::uint64_t resume = oldest > next ? oldest : next + 1;
        std::fprintf(stderr, "# skipped %llu records (fell behind the writer)\n",
                     static_cast<unsigned long long>(resume - next));
        next = resume;
        break;
      }
      case nao::AttentionRead::kNotYetWritten: sleepMs(interval_ms); break;
      case nao::AttentionRead::kTorn:
        std::fprintf(stderr, "nao_attn_tail: attention ring %s: record %llu stays half-written (writer stopped mid-push?)\n",
                     shm.name().c_str(), static_cast<unsigned long long>(next));
        return 1;
    }
  }
  return 0;
}
