// Real-time property: pushing attention records (and sealing them) allocates nothing, into an
// in-process ring or one in shared memory; neither does reading them.
#include "nao/attention_ring.hpp"
#include "nao/attention_shm.hpp"
#include "support/alloc_counter.hpp"

#include <doctest/doctest.h>

#include <memory>
#include <random>
#include <string>

#include <unistd.h>

using namespace nao;
using nao::test::CountAllocations;

namespace {

using PaperPayload = AttentionPayload<4, 4, 128, 20>;
using PaperRing = AttentionRing<PaperPayload>;
constexpr int kPushes = 10000;

// Pushes kPushes sealed records (payload changed every push) and reads each back; returns the
// allocations counted on this thread meanwhile. Everything is built before counting starts.
std::int64_t pushAndRead(PaperRing& ring, const PaperRing& reader_side) {
  auto p = std::make_unique<PaperPayload>();
  auto out = std::make_unique<PaperPayload>();
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int n_ok = 0;
  CountAllocations counter;
  for (int i = 0; i < kPushes; ++i) {
    p->tick = static_cast<std::uint64_t>(i);
    for (float& v : p->score) v = u(rng);
    p->cross_out[i % 5][i % 128] = u(rng);
    sealPayload(*p);
    const std::uint64_t record = pushFromRT(ring, *p);
    n_ok += readFromNonRT(reader_side, record, *out) == AttentionRead::kOk && payloadIntact(*out);
    n_ok -= !latestRecord(reader_side).has_value();
  }
  closeFromRT(ring);
  const std::int64_t n_alloc = counter.count();
  CHECK(n_ok == kPushes);
  return n_alloc;
}

}  // namespace

TEST_CASE("10,000 pushFromRT into an in-process ring allocate nothing") {
  auto ring = std::make_unique<PaperRing>(attentionPayloadDescriptor<PaperPayload>());
  const std::int64_t n_alloc = pushAndRead(*ring, *ring);
  CHECK_MESSAGE(n_alloc == 0, "expected no heap allocation in " << kPushes << " pushes, got " << n_alloc);
}

TEST_CASE("10,000 pushFromRT into a shared-memory ring, read through a read-only mapping, allocate nothing") {
  const std::string name = "/nao_rt_test_attn_alloc_" + std::to_string(::getpid());
  SharedAttentionRing<PaperRing> writer(name, attentionPayloadDescriptor<PaperPayload>());
  const AttentionShm reader = AttentionShm::openReadOnly(name);
  const std::int64_t n_alloc = pushAndRead(writer.ring(), attachAttentionRing<PaperRing>(reader));
  CHECK_MESSAGE(n_alloc == 0, "expected no heap allocation in " << kPushes << " pushes, got " << n_alloc);
}
