// Reduced-precision weights (nao/quantize.hpp, policy_kernels.hpp "Reduced precision"):
// - quantizeMatrixInt8 keeps every weight within half a step of its row's scale, in the pair
//   layout the kernels read;
// - the SSE2/SSSE3, AVX2 and AVX-512 int8 kernels give the same bits, equal to exact int64 sums
//   through the same epilogue, up to the largest accumulator the layout allows (In = 512, all
//   ±127 · ±32767), with 16-bit signed tokens and with 7-bit non-negative ones (pmaddubsw;
//   AVX-512: vpdpbusd);
// - no pmaddubsw pair sum saturates, whatever the weight bytes and 7-bit token bytes: the
//   extreme values through the instruction and through every kernel against int64 sums;
// - the int8 product stays within the bound that quantising W and X allows of the fp32 product;
// - the blob made from the file (manifest order) and from the bound views (visitQuantViews
//   order) are the same bytes, so the binder points every view at its own matrix;
// - stepPolicy with int8 views: the same bits under both kernels, close to fp32, and back to
//   fp32 bit for bit when the views are dropped.
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "nao/arm_model.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

using namespace nao;

namespace {

bool haveAvx2() { return policyKernelSupported(PolicyKernel::kAvx2); }
bool haveAvx512() { return policyKernelSupported(PolicyKernel::kAvx512); }


std::vector<float> randomVector(std::mt19937_64& rng, std::size_t n, double lo, double hi) {
  std::vector<float> v(n);
  for (float& x : v) x = test::uniformFloat(rng, lo, hi);
  return v;
}

/// The blob section of one random [Out, In] matrix.
struct QuantMatrix {
  std::vector<float> w;           ///< column-major [Out, In]
  std::vector<std::uint8_t> sec;  ///< quantSectionBytes(Out, In)
  const std::int8_t* q() const { return reinterpret_cast<const std::int8_t*>(sec.data()); }
  const float* scale(int out, int in) const {
    return reinterpret_cast<const float*>(sec.data() + detail::quantPad(static_cast<std::size_t>(out) * in));
  }
};

QuantMatrix makeQuantMatrix(std::mt19937_64& rng, int out, int in) {
  QuantMatrix m;
  m.w = randomVector(rng, static_cast<std::size_t>(out) * in, -0.3, 0.3);
  m.sec.assign(detail::quantSectionBytes(out, in), 0);
  quantizeMatrixInt8(m.w.data(), out, in, m.sec.data());
  return m;
}

/// The int8 product by definition: exact int64 sums of the quantised values, then the kernels'
/// own epilogue.
template <int Out, int In, int J, bool kRelu>
std::vector<float> int8Reference(const QuantMatrix& m, const float* b, const float* X) {
  detail::QuantTokens<In, J> x;
  detail::quantizeTokensInt8<In, J>(X, x);
  std::vector<std::int32_t> acc(static_cast<std::size_t>(Out) * J);
  for (int t = 0; t < J; ++t)
    for (int r = 0; r < Out; ++r) {
      std::int64_t s = 0;
      for (int k = 0; k < In; ++k)
        s += static_cast<std::int64_t>(m.q()[(static_cast<std::size_t>(k / 2) * Out + r) * 2 + k % 2]) *
             detail::quantToken(x, k, t);
      REQUIRE(s <= std::numeric_limits<std::int32_t>::max());
      REQUIRE(s >= std::numeric_limits<std::int32_t>::min());
      acc[static_cast<std::size_t>(t * Out + r)] = static_cast<std::int32_t>(s);
    }
  std::vector<float> y(static_cast<std::size_t>(Out) * J);
  detail::dequantizeTokens<Out, J, kRelu>(acc.data(), m.scale(Out, In), x.sx, b, y.data());
  return y;
}

/// x_lo: the inputs are uniform in [x_lo, 2]; x_lo >= 0 gives the unsigned range [0, 127].
template <int Out, int In, int J>
void checkInt8Shape(std::uint64_t seed, double x_lo = -2.0) {
  CAPTURE(Out);
  CAPTURE(In);
  CAPTURE(x_lo);
  std::mt19937_64 rng(seed);
  const QuantMatrix m = makeQuantMatrix(rng, Out, In);
  const std::vector<float> b = randomVector(rng, Out, -0.5, 0.5);
  std::vector<float> X = randomVector(rng, static_cast<std::size_t>(In) * J, x_lo, 2.0);
  if (x_lo >= 0.0)  // zeros as a ReLU leaves them
    for (std::size_t i = 0; i < X.size(); i += 3) X[i] = 0.0f;
  const std::vector<float> want = int8Reference<Out, In, J, true>(m, b.data(), X.data());
  std::vector<float> sse(want.size()), avx(want.size());
  detail::affineTokensInt8<Out, In, J, true>(PolicyKernel::kSse, m.q(), m.scale(Out, In), b.data(), X.data(), sse.data());
  CHECK(std::memcmp(sse.data(), want.data(), want.size() * sizeof(float)) == 0);
  if (haveAvx2()) {
    detail::affineTokensInt8<Out, In, J, true>(PolicyKernel::kAvx2, m.q(), m.scale(Out, In), b.data(), X.data(), avx.data());
    CHECK(std::memcmp(avx.data(), want.data(), want.size() * sizeof(float)) == 0);
  }
  if (haveAvx512()) {
    std::fill(avx.begin(), avx.end(), NAN);
    detail::affineTokensInt8<Out, In, J, true>(PolicyKernel::kAvx512, m.q(), m.scale(Out, In), b.data(), X.data(), avx.data());
    CHECK(std::memcmp(avx.data(), want.data(), want.size() * sizeof(float)) == 0);
  }

  // Within what quantisation allows of fp32: |ΔW| <= sw/2 per weight and |Δx| <= sx/2 per input,
  // so |Δy| <= Σ_k (sw/2 |x_k| + |W_k| sx/2 + sw sx/4), plus float rounding (1e-5 relative).
  std::vector<float> fp(want.size());
  detail::affineTokens<Out, In, J, false>(PolicyKernel::kSse, m.w.data(), b.data(), X.data(), fp.data());
  const float* sw = m.scale(Out, In);
  for (int t = 0; t < J; ++t) {
    float mx = 0.0f;
    for (int k = 0; k < In; ++k) mx = std::max(mx, std::fabs(X[static_cast<std::size_t>(t * In + k)]));
    const double sx = mx / detail::int8TokenLevels(x_lo >= 0.0);
    for (int r = 0; r < Out; ++r) {
      double bound = 0.0, mag = 0.0;
      for (int k = 0; k < In; ++k) {
        const double x = std::fabs(X[static_cast<std::size_t>(t * In + k)]);
        const double w = std::fabs(m.w[static_cast<std::size_t>(k) * Out + r]);
        bound += sw[r] / 2.0 * x + w * sx / 2.0 + sw[r] * sx / 4.0;
        mag += w * x;
      }
      bound += 1e-5 * (mag + std::fabs(b[static_cast<std::size_t>(r)]));
      const double y8 = sse[static_cast<std::size_t>(t * Out + r)];
      const double y32 = std::max(0.0f, fp[static_cast<std::size_t>(t * Out + r)]);
      CHECK(std::fabs(y8 - y32) <= bound);
    }
  }
}

}  // namespace

TEST_CASE("quantizeMatrixInt8: one scale per row, every weight within half a step, pairs interleaved") {
  constexpr int Out = 24, In = 10;
  std::mt19937_64 rng(5);
  QuantMatrix m = makeQuantMatrix(rng, Out, In);
  const float* s = m.scale(Out, In);
  for (int r = 0; r < Out; ++r) {
    float mx = 0.0f;
    for (int k = 0; k < In; ++k) mx = std::max(mx, std::fabs(m.w[static_cast<std::size_t>(k) * Out + r]));
    CHECK(s[r] == mx / 127.0f);
    bool hit_max = false;
    for (int k = 0; k < In; ++k) {
      const int q = m.q()[(static_cast<std::size_t>(k / 2) * Out + r) * 2 + k % 2];
      CHECK(std::abs(q) <= 127);
      CHECK(std::fabs(static_cast<float>(q) * s[r] - m.w[static_cast<std::size_t>(k) * Out + r]) <= 0.5f * s[r] * (1.0f + 1e-5f));
      hit_max = hit_max || std::abs(q) == 127;
    }
    CHECK(hit_max);  // the largest weight of the row uses the whole range
  }
  // An all-zero row: scale 0, zero bytes (the kernel then gives the bias).
  std::vector<float> zero(static_cast<std::size_t>(Out) * In, 0.0f);
  quantizeMatrixInt8(zero.data(), Out, In, m.sec.data());
  CHECK(m.scale(Out, In)[3] == 0.0f);
  CHECK(m.q()[6] == 0);
}

TEST_CASE("int8 kernels: SSE2 and AVX2 equal exact integer sums bit for bit, and stay within the quantisation bound of fp32") {
  checkInt8Shape<32, 64, 5>(1);
  checkInt8Shape<64, 32, 5>(2);
  checkInt8Shape<24, 10, 3>(3);  // 3 blocks of 8 rows, a strip of 5 pairs
  checkInt8Shape<20, 6, 5>(4);   // 4 leftover rows (the scalar path)
  checkInt8Shape<128, 128, 5>(5);
  checkInt8Shape<512, 128, 5>(6);
  checkInt8Shape<128, 512, 5>(7);
  checkInt8Shape<512, 512, 5>(8);
  checkInt8Shape<128, 32, 5>(9);
  checkInt8Shape<48, 34, 5>(10);  // the AVX-512 blocks of 32 and 16 rows, a partial strip
  checkInt8Shape<40, 6, 3>(11);   // a block of 32, then 8 scalar rows
  // Non-negative inputs: the 7-bit unsigned range (pmaddubsw; vpdpbusd on AVX-512).
  checkInt8Shape<512, 512, 5>(12, 0.0);
  checkInt8Shape<128, 512, 5>(13, 0.0);
  checkInt8Shape<48, 36, 5>(14, 0.0);
  checkInt8Shape<40, 6, 3>(15, 0.0);
  checkInt8Shape<48, 36, 5>(16);
  checkInt8Shape<56, 128, 5>(17, 0.0);  // AVX2: blocks of 16 rows, then 8 (SSSE3 lanes)
  checkInt8Shape<60, 64, 4>(18, 0.0);   // and 4 scalar rows
  checkInt8Shape<24, 10, 3>(19, 0.0);   // In % 4 != 0: no quads, the pmaddwd kernels
  if (!haveAvx2()) MESSAGE("AVX2 is not available on this CPU (or build): only the SSE2 int8 kernel was checked");
  if (!haveAvx512()) MESSAGE("AVX-512 VNNI is not available on this CPU (or build): the avx512 int8 kernel was not checked");
}

namespace {

/// quantizeTokensInt8 against its definition with scalar nearbyint (In = 64: the SSE2 path;
/// In = 10: its scalar tail), over signed inputs (16 bits, ±32767) and non-negative ones (7 bits,
/// 0 .. 127, also as the byte quads).
template <int In>
void checkTokenQuantisation(std::uint64_t seed, bool non_negative) {
  CAPTURE(In);
  CAPTURE(non_negative);
  constexpr int J = 4;
  std::mt19937_64 rng(seed);
  std::vector<float> X = randomVector(rng, static_cast<std::size_t>(In) * J, non_negative ? 0.0 : -3.0, 3.0);
  X[static_cast<std::size_t>(2 * In + 5)] = 7.5f;  // the column's max maps to the top level
  detail::QuantTokens<In, J> x;
  detail::quantizeTokensInt8<In, J>(X.data(), x);
  CHECK(x.positive == non_negative);
  const float levels = non_negative ? 127.0f : 32767.0f;
  CHECK(detail::int8TokenLevels(non_negative) == levels);
  for (int t = 0; t < J; ++t) {
    float m = 0.0f;
    for (int k = 0; k < In; ++k) m = std::max(m, std::fabs(X[static_cast<std::size_t>(t * In + k)]));
    CHECK(x.sx[t] == m / levels);
    const float inv = levels / m;
    for (int k = 0; k < In; ++k)
      CHECK(detail::quantToken(x, k, t) == static_cast<int>(std::nearbyint(X[static_cast<std::size_t>(t * In + k)] * inv)));
  }
  CHECK(detail::quantToken(x, 5, 2) == static_cast<int>(levels));
  if constexpr (detail::QuantTokens<In, J>::kQuads > 0) {
    if (non_negative)
      for (int t = 0; t < J; ++t)
        for (int k = 0; k < In; ++k) {
          const auto byte = reinterpret_cast<const std::uint8_t*>(x.quads)[t * In + k];
          CHECK(static_cast<int>(byte) == detail::quantToken(x, k, t));
          CHECK(byte <= 127);
        }
  }
#if NAO_POLICY_HAVE_AVX2
  if (haveAvx512()) {  // the 16-lane quantiser: the same values and scales, and the 8-bit quads
    detail::QuantTokens<In, J> x512;
    std::memset(&x512, 0xff, sizeof x512);
    detail::quantizeTokensInt8Avx512<In, J>(X.data(), x512);
    CHECK(std::memcmp(x512.pairs, x.pairs, sizeof x.pairs) == 0);
    CHECK(std::memcmp(x512.sx, x.sx, sizeof x.sx) == 0);
    CHECK(x512.positive == x.positive);
    if constexpr (detail::QuantTokens<In, J>::kQuads > 0) {
      if (non_negative)
        for (int t = 0; t < J; ++t)
          for (int k = 0; k < In; ++k) {
            const auto byte = reinterpret_cast<const std::uint8_t*>(x512.quads)[t * In + k];
            CHECK(static_cast<int>(byte) == detail::quantToken(x, k, t));
          }
    }
  }
#endif
}

}  // namespace

TEST_CASE("quantizeTokensInt8: per-column scale, round to nearest even, the column's max at the top level") {
  for (const bool non_negative : {false, true}) {
    checkTokenQuantisation<64>(31, non_negative);
    checkTokenQuantisation<40>(33, non_negative);  // two 16-lane blocks and a scalar tail of 8
    checkTokenQuantisation<10>(32, non_negative);
  }
  // One negative entry anywhere in the product puts every column in the signed range.
  std::vector<float> X(2 * 8, 1.0f);
  X[11] = -1e-3f;
  detail::QuantTokens<8, 2> x;
  detail::quantizeTokensInt8<8, 2>(X.data(), x);
  CHECK_FALSE(x.positive);
  CHECK(detail::quantToken(x, 0, 0) == 32767);
}

TEST_CASE("int8 kernels: the largest accumulator the layout allows does not overflow") {
  // In = 512 with every weight and every input at full scale: Σ = 512 · 127 · 32767 < 2^31 in the
  // signed range, 512 · 127 · 127 in the unsigned one (pmaddubsw; vpdpbusd on AVX-512).
  constexpr int Out = 16, In = detail::kInt8MaxIn, J = 2;
  QuantMatrix m;
  m.w.assign(static_cast<std::size_t>(Out) * In, 1.0f);
  for (int r = 0; r < Out; r += 2)
    for (int k = 0; k < In; ++k) m.w[static_cast<std::size_t>(k) * Out + r] = -1.0f;
  m.sec.assign(detail::quantSectionBytes(Out, In), 0);
  quantizeMatrixInt8(m.w.data(), Out, In, m.sec.data());
  for (const float second : {-3.0f, 3.0f}) {  // token 1 negative (signed range), then positive
    CAPTURE(second);
    std::vector<float> X(static_cast<std::size_t>(In) * J, 3.0f);
    for (int k = 0; k < In; ++k) X[static_cast<std::size_t>(In + k)] = second;
    const std::vector<float> want = int8Reference<Out, In, J, false>(m, nullptr, X.data());
    for (PolicyKernel k : {PolicyKernel::kSse, PolicyKernel::kAvx2, PolicyKernel::kAvx512}) {
      if (!policyKernelSupported(k)) continue;
      std::vector<float> y(want.size());
      detail::affineTokensInt8<Out, In, J, false>(k, m.q(), m.scale(Out, In), nullptr, X.data(), y.data());
      CHECK(std::memcmp(y.data(), want.data(), want.size() * sizeof(float)) == 0);
      // 512 · (±1) · (±3) exactly, up to the scales' float rounding.
      CHECK(y[0] == doctest::Approx(-1536.0).epsilon(1e-6));
      CHECK(y[1] == doctest::Approx(1536.0).epsilon(1e-6));
      CHECK(y[Out] == doctest::Approx(second < 0.0f ? 1536.0 : -1536.0).epsilon(1e-6));
    }
  }
}

namespace {

/// Σ_k Wq(r, k) · xq(k, t) in int64 straight from the blob's bytes (pairs layout) and the
/// tokens' bytes: the reference every kernel's int32 sums must equal.
template <int Out, int In, int J>
std::vector<std::int32_t> exactSums(const std::vector<std::int8_t>& wq, const std::vector<std::uint8_t>& xb) {
  std::vector<std::int32_t> acc(static_cast<std::size_t>(Out) * J);
  for (int t = 0; t < J; ++t)
    for (int r = 0; r < Out; ++r) {
      std::int64_t s = 0;
      for (int k = 0; k < In; ++k)
        s += static_cast<std::int64_t>(wq[(static_cast<std::size_t>(k / 2) * Out + r) * 2 + k % 2]) *
             xb[static_cast<std::size_t>(t * In + k)];
      REQUIRE(s <= std::numeric_limits<std::int32_t>::max());
      REQUIRE(s >= std::numeric_limits<std::int32_t>::min());
      acc[static_cast<std::size_t>(t * Out + r)] = static_cast<std::int32_t>(s);
    }
  return acc;
}

/// Quantised tokens made from raw bytes (as quantizeTokensInt8 leaves 7-bit ones): quads, the
/// same values as int16 pairs, positive.
template <int In, int J>
void tokensFromBytes(const std::vector<std::uint8_t>& xb, detail::QuantTokens<In, J>& x) {
  std::memcpy(x.quads, xb.data(), static_cast<std::size_t>(In) * J);
  for (int t = 0; t < J; ++t)
    for (int p = 0; p < In / 2; ++p)
      x.pairs[t * (In / 2) + p] = static_cast<std::int32_t>(xb[static_cast<std::size_t>(t * In + 2 * p)] |
                                                            (static_cast<std::uint32_t>(xb[static_cast<std::size_t>(t * In + 2 * p + 1)]) << 16));
  for (int t = 0; t < J; ++t) x.sx[t] = 1.0f;
  x.positive = true;
}

/// Every kernel that can run here on weight bytes `wq` and token bytes `xb` (7-bit quads and the
/// pmaddwd pairs), each against exactSums. Returns how many kernels ran.
template <int Out, int In, int J>
int checkAllKernelSums(const std::vector<std::int8_t>& wq, const std::vector<std::uint8_t>& xb) {
  const std::vector<std::int32_t> want = exactSums<Out, In, J>(wq, xb);
  detail::QuantTokens<In, J> x;
  tokensFromBytes<In, J>(xb, x);
  std::vector<std::int32_t> acc(want.size());
  int ran = 0;
  const auto check = [&](const char* kernel) {
    CAPTURE(kernel);
    CHECK(acc == want);
    std::fill(acc.begin(), acc.end(), 0x5a5a5a5a);
    ++ran;
  };
  detail::accumulateRowsInt8Scalar<Out, In, J>(wq.data(), x.pairs, acc.data(), 0);
  check("scalar");
#if defined(__SSE2__)
  detail::accumulateInt8Sse<Out, In, J>(wq.data(), x.pairs, acc.data());
  check("sse2 pmaddwd");
#endif
#if defined(__SSE2__) && defined(__GNUC__)
  if (detail::int8HaveSsse3()) {
    detail::accumulateInt8QuadsSsse3<Out, In, J>(wq.data(), x, acc.data());
    check("ssse3 pmaddubsw");
  }
#endif
#if NAO_POLICY_HAVE_AVX2
  if (haveAvx2()) {
    detail::accumulateInt8Avx2<Out, In, J>(wq.data(), x.pairs, acc.data());
    check("avx2 pmaddwd");
    detail::accumulateInt8QuadsAvx2<Out, In, J>(wq.data(), x, acc.data());
    check("avx2 pmaddubsw");
  }
  if (haveAvx512()) {
    detail::accumulateInt8Avx512<Out, In, J>(wq.data(), x.pairs, acc.data());
    check("avx512 vpdpwssd");
    detail::accumulateInt8QuadsAvx512<Out, In, J>(wq.data(), x, acc.data());
    check("avx512 vpdpbusd");
  }
#endif
  return ran;
}

}  // namespace

#if defined(__SSE2__) && defined(__GNUC__)
namespace {
/// One pmaddubsw: 16 unsigned bytes a times 16 signed bytes w, adjacent products added into 8
/// int16 (saturating).
__attribute__((target("ssse3"), noinline)) void maddubs(const std::uint8_t* a, const std::int8_t* w, std::int16_t* out) {
  _mm_store_si128(reinterpret_cast<__m128i*>(out), _mm_maddubs_epi16(_mm_load_si128(reinterpret_cast<const __m128i*>(a)),
                                                                     _mm_load_si128(reinterpret_cast<const __m128i*>(w))));
}
}  // namespace

TEST_CASE("pmaddubsw: a pair sum of 7-bit token bytes and any weight bytes is exact at the extremes") {
  // |a0·w0 + a1·w1| <= 2 · 127 · 128 = 32512 < 32767: every corner of a in [0, 127] and w in
  // [-128, 127] (the blob holds ±127; -128 too, to show the margin), through the instruction.
  if (!detail::int8HaveSsse3()) {
    MESSAGE("SSSE3 is not available on this CPU: the pmaddubsw kernels do not run here");
    return;
  }
  const int as[] = {0, 1, 63, 64, 126, 127};
  const int ws[] = {-128, -127, -64, -1, 0, 1, 64, 126, 127};
  int checked = 0, largest = 0;
  for (int a0 : as)
    for (int a1 : as)
      for (int w0 : ws)
        for (int w1 : ws) {
          alignas(16) std::uint8_t a[16];
          alignas(16) std::int8_t w[16];
          for (int i = 0; i < 16; i += 2) {
            a[i] = static_cast<std::uint8_t>(a0);
            a[i + 1] = static_cast<std::uint8_t>(a1);
            w[i] = static_cast<std::int8_t>(w0);
            w[i + 1] = static_cast<std::int8_t>(w1);
          }
          alignas(16) std::int16_t out[8];
          maddubs(a, w, out);
          const int want = a0 * w0 + a1 * w1;
          for (int i = 0; i < 8; ++i) CHECK(out[i] == want);
          largest = std::max(largest, std::abs(want));
          ++checked;
        }
  CHECK(checked == 6 * 6 * 9 * 9);
  CHECK(largest == 32512);
}
#endif

TEST_CASE("int8 kernels: no saturation whatever the weights and 7-bit tokens (extreme bytes, every kernel = int64 sums)") {
  // Out = 56: AVX2 blocks of 16 rows and one of 8, AVX-512 blocks of 32 and 16 and scalar rows;
  // In = 512, the largest accumulator.
  constexpr int Out = 56, In = detail::kInt8MaxIn, J = 3;
  const std::size_t nw = static_cast<std::size_t>(Out) * In, nx = static_cast<std::size_t>(In) * J;
  std::mt19937_64 rng(40);
  std::uniform_int_distribution<int> any_w(-128, 127), any_x(0, 127);
  // Weight patterns: all at one extreme, alternating extremes (pairs of opposite sign), random
  // over every byte. Token patterns: all 127, alternating 127 / 0, random over [0, 127].
  const std::vector<int> extremes = {127, -127, -128};
  std::vector<std::vector<std::int8_t>> weights;
  for (int e : extremes) weights.emplace_back(nw, static_cast<std::int8_t>(e));
  {
    std::vector<std::int8_t> alt(nw), rnd(nw);
    for (std::size_t i = 0; i < nw; ++i) {
      alt[i] = static_cast<std::int8_t>(i % 2 == 0 ? 127 : -128);
      rnd[i] = static_cast<std::int8_t>(any_w(rng));
    }
    weights.push_back(alt);
    weights.push_back(rnd);
  }
  std::vector<std::vector<std::uint8_t>> tokens;
  tokens.emplace_back(nx, std::uint8_t{127});
  {
    std::vector<std::uint8_t> alt(nx), rnd(nx);
    for (std::size_t i = 0; i < nx; ++i) {
      alt[i] = static_cast<std::uint8_t>(i % 4 < 2 ? 127 : 0);
      rnd[i] = static_cast<std::uint8_t>(any_x(rng));
    }
    tokens.push_back(alt);
    tokens.push_back(rnd);
  }
  int runs = 0;
  for (std::size_t wi = 0; wi < weights.size(); ++wi)
    for (std::size_t xi = 0; xi < tokens.size(); ++xi) {
      CAPTURE(wi);
      CAPTURE(xi);
      runs += checkAllKernelSums<Out, In, J>(weights[wi], tokens[xi]);
    }
  CHECK(runs >= 2 * 15);  // at least the scalar and pmaddwd kernels on every pattern
  // The worst row: 512 · 127 · (-128) exactly.
  CHECK(exactSums<Out, In, J>(weights[2], tokens[0])[0] == -512 * 127 * 128);
#if defined(__SSE2__) && defined(__GNUC__)
  // The bound is tight where it matters: token bytes of 8 bits (255) would saturate pmaddubsw
  // (255 · 127 · 2 > 32767), and this test would see it.
  if (detail::int8HaveSsse3()) {
    const std::vector<std::uint8_t> eight_bit(nx, std::uint8_t{255});
    detail::QuantTokens<In, J> x;
    tokensFromBytes<In, J>(eight_bit, x);
    std::vector<std::int32_t> acc(static_cast<std::size_t>(Out) * J);
    detail::accumulateInt8QuadsSsse3<Out, In, J>(weights[0].data(), x, acc.data());
    CHECK(acc != exactSums<Out, In, J>(weights[0], eight_bit));
    CHECK(acc[0] == 32767 * (In / 2));  // every pair clipped to the int16 maximum
  }
#endif
}

TEST_CASE("int8 kernels: NaN stays NaN through the ReLU, and a column too small to scale is zero") {
  constexpr int Out = 36, In = 8, J = 2;  // 36 rows: the SSE2 lanes and the scalar tail
  std::mt19937_64 rng(12);
  const QuantMatrix m = makeQuantMatrix(rng, Out, In);
  const std::vector<float> b = randomVector(rng, Out, -0.5, 0.5);
  std::vector<float> X(static_cast<std::size_t>(In) * J, 0.0f);
  X[2] = std::numeric_limits<float>::quiet_NaN();             // token 0
  for (int k = 0; k < In; ++k) X[static_cast<std::size_t>(In + k)] = k % 2 == 0 ? 1e-36f : -1e-36f;  // token 1
  for (PolicyKernel k : {PolicyKernel::kSse, PolicyKernel::kAvx2, PolicyKernel::kAvx512}) {
    if (!policyKernelSupported(k)) continue;
    std::vector<float> y(static_cast<std::size_t>(Out) * J);
    detail::affineTokensInt8<Out, In, J, true>(k, m.q(), m.scale(Out, In), b.data(), X.data(), y.data());
    for (int r = 0; r < Out; ++r) {
      CHECK(std::isnan(y[static_cast<std::size_t>(r)]));  // as std::max(NaN, 0) in the fp32 path
      // 32767 / 1e-36 overflows: the column counts as zero, the output is the bias (ReLU'd).
      CHECK(y[static_cast<std::size_t>(Out + r)] == std::max(b[static_cast<std::size_t>(r)], 0.0f));
    }
  }
  // quantizeMatrixInt8 refuses what the layout cannot hold.
  std::vector<std::uint8_t> sec(detail::quantSectionBytes(4, 3));
  std::vector<float> w(12, 0.5f);
  CHECK_THROWS_AS(quantizeMatrixInt8(w.data(), 4, 3, sec.data()), std::invalid_argument);
}

TEST_CASE("int8 kernels: a non-finite token gives NaN outputs, an all-zero token the bias") {
  constexpr int Out = 32, In = 16, J = 3;
  std::mt19937_64 rng(8);
  const QuantMatrix m = makeQuantMatrix(rng, Out, In);
  const std::vector<float> b = randomVector(rng, Out, -0.5, 0.5);
  std::vector<float> X = randomVector(rng, static_cast<std::size_t>(In) * J, -1.0, 1.0);
  X[3] = std::numeric_limits<float>::infinity();          // token 0
  for (int k = 0; k < In; ++k) X[static_cast<std::size_t>(In + k)] = 0.0f;  // token 1
  std::vector<float> y(static_cast<std::size_t>(Out) * J);
  detail::affineTokensInt8<Out, In, J, false>(bestPolicyKernel(), m.q(), m.scale(Out, In), b.data(), X.data(), y.data());
  for (int r = 0; r < Out; ++r) {
    CHECK(std::isnan(y[static_cast<std::size_t>(r)]));
    CHECK(y[static_cast<std::size_t>(Out + r)] == b[static_cast<std::size_t>(r)]);
    CHECK(std::isfinite(y[static_cast<std::size_t>(2 * Out + r)]));
  }
}

namespace {

/// quantizeModelInt8 of a file with random tensors equals quantizePolicyInt8 of the views
/// bound to the same tensors, and has the layout's size.
template <class Dims>
void checkBlobOrder(std::uint64_t seed) {
  ModelHeader h;
  h.arch = Dims::arch();
  for (int j = 0; j < h.arch.tokens; ++j) h.joints.push_back({"j" + std::to_string(j), -1.0, 1.0, 2.0});
  for (int mv = 0; mv < h.arch.movements; ++mv) h.movement_names.push_back("m" + std::to_string(mv));
  h.metadata_json = "{}";
  const std::vector<std::vector<float>> tensors = test::randomManifestTensors(h.arch, seed);
  const ModelFile file = decodeModel(encodeModel(h, tensors), "random model");
  const AlignedBytes from_file = quantizeModelInt8(file);
  CHECK(from_file.size == quantizedPolicyBytes<Dims>());
  CHECK(quantizedModelBytes(h.arch) == quantizedPolicyBytes<Dims>());
  std::vector<const float*> ptrs;
  for (const auto& t : tensors) ptrs.push_back(t.data());
  const PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), h.arch, Conditioning::kReference);
  const AlignedBytes from_views = quantizePolicyInt8(w);
  REQUIRE(from_views.size == from_file.size);
  CHECK(std::memcmp(from_views.data.get(), from_file.data.get(), from_file.size) == 0);
  // And the binder's pointers land on the sections of their own matrices.
  PolicyWeights<Dims> bound = w;
  bindQuantizedWeights<Dims>(bound, from_file.data.get());
  CHECK(usesInt8(bound));
  int checked = 0;
  detail::visitQuantViews(bound, [&](const auto& view, const auto& q) {
    using V = std::remove_reference_t<decltype(view)>;
    constexpr int out = V::RowsAtCompileTime, in = V::ColsAtCompileTime;
    std::vector<std::uint8_t> sec(detail::quantSectionBytes(out, in));
    quantizeMatrixInt8(view.data(), out, in, sec.data());
    CHECK(std::memcmp(q.w, sec.data(), static_cast<std::size_t>(out) * in) == 0);
    CHECK(std::memcmp(q.scale, sec.data() + detail::quantPad(static_cast<std::size_t>(out) * in), out * sizeof(float)) == 0);
    ++checked;
  });
  CHECK(checked == 8 * Dims::kEncoderLayers + 12 * Dims::kDecoderLayers);
  unbindQuantizedWeights<Dims>(bound);
  CHECK_FALSE(usesInt8(bound));
}

/// Runs `ticks` steps of one stream with weights `w`; returns every action.
template <class Dims>
std::vector<float> rollActions(const PolicyWeights<Dims>& w, std::uint64_t seed, int ticks) {
  auto ws = makePolicyWorkspace<Dims>();
  resetPolicyStream(*ws);
  std::mt19937_64 rng(seed);
  std::vector<float> out;
  for (int t = 0; t < ticks; ++t) {
    const PolicyInput in = test::randomPolicyInput(rng, t % w.movements, t, 1.2);
    const auto& a = stepPolicy(w, *ws, in);
    out.insert(out.end(), a.data(), a.data() + 5);
  }
  return out;
}

}  // namespace

TEST_CASE("the int8 blob from the file equals the one from the bound views (manifest order = view order)") {
  checkBlobOrder<SmallPolicyDims>(11);
  checkBlobOrder<PaperPolicyDims>(12);
}

namespace {

ModelFile modelOf(const PolicyArch& arch) {
  ModelHeader h;
  h.arch = arch;
  for (int j = 0; j < h.arch.tokens; ++j) h.joints.push_back({"j" + std::to_string(j), -1.0, 1.0, 2.0});
  for (int mv = 0; mv < h.arch.movements; ++mv) h.movement_names.push_back("m" + std::to_string(mv));
  h.metadata_json = "{}";
  return decodeModel(encodeModel(h, test::randomManifestTensors(h.arch, 3)), "odd model");
}

}  // namespace

TEST_CASE("quantizeModelInt8 refuses an odd head size or a matrix with an odd number of inputs") {
  static_assert(!int8Supported<PolicyDims<36, 4, 1, 2, 20, 13, 7>>());
  static_assert(int8Supported<SmallPolicyDims>() && int8Supported<PaperPolicyDims>());
  CHECK_THROWS_WITH_AS(quantizeModelInt8(modelOf(PolicyDims<36, 4, 1, 2, 20, 14, 8>::arch())),
                       doctest::Contains("head size 9 is odd"), ModelFileError);
  CHECK_THROWS_WITH_AS(quantizeModelInt8(modelOf(PolicyDims<32, 4, 1, 2, 20, 13, 8>::arch())),
                       doctest::Contains("13 inputs"), ModelFileError);
}

TEST_CASE("stepPolicy with int8 weights: same bits under every kernel, near fp32, fp32 again when unbound") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const test::RandomPolicy p = test::makeRandomPolicy(SmallPolicyDims::arch(), arm, 21);
  PolicyWeights<SmallPolicyDims> w =
      bindPolicyWeights<SmallPolicyDims>(p.pointers.data(), p.pointers.size(), SmallPolicyDims::arch(),
                                         Conditioning::kReference, PolicyKernel::kSse);
  constexpr int kTicks = 40;  // window 8: the rings wrap
  const std::vector<float> fp32 = rollActions(w, 4, kTicks);
  const AlignedBytes blob = quantizePolicyInt8(w);
  bindQuantizedWeights<SmallPolicyDims>(w, blob.data.get());
  const std::vector<float> q_sse = rollActions(w, 4, kTicks);
  CHECK(rollActions(w, 4, kTicks) == q_sse);  // deterministic
  if (haveAvx2()) {
    PolicyWeights<SmallPolicyDims> w_avx = w;  // the same int8 copy, another kernel
    setPolicyKernel(w_avx, PolicyKernel::kAvx2);
    const std::vector<float> q_avx = rollActions(w_avx, 4, kTicks);
    CHECK(std::memcmp(q_avx.data(), q_sse.data(), q_sse.size() * sizeof(float)) == 0);
    if (haveAvx512()) {
      setPolicyKernel(w_avx, PolicyKernel::kAvx512);
      const std::vector<float> q_512 = rollActions(w_avx, 4, kTicks);
      CHECK(std::memcmp(q_512.data(), q_sse.data(), q_sse.size() * sizeof(float)) == 0);
    }
  } else {
    MESSAGE("AVX2 is not available on this CPU (or build): only the SSE2 int8 kernel was checked");
  }
  // Near fp32 and not equal to it (the int8 path really ran).
  double max_diff = 0.0, max_abs = 0.0;
  for (std::size_t i = 0; i < fp32.size(); ++i) {
    max_diff = std::max(max_diff, std::fabs(static_cast<double>(q_sse[i]) - fp32[i]));
    max_abs = std::max(max_abs, std::fabs(static_cast<double>(fp32[i])));
  }
  MESSAGE("small random policy, 40 ticks: max |a_int8 - a_fp32| = " << max_diff << " of max |a| = " << max_abs);
  // A coarse sanity bound for random weights (measured 1.9 % with 7-bit unsigned tokens; 1.7 %
  // with 8-bit ones, 1.6 % with 16-bit tokens everywhere); the trained models' action differences
  // and closed-loop hand errors are measured in bench/int8_accuracy.py.
  CHECK(max_diff > 0.0);
  CHECK(max_diff <= 0.02 * max_abs);
  unbindQuantizedWeights<SmallPolicyDims>(w);
  CHECK(rollActions(w, 4, kTicks) == fp32);
}

TEST_CASE("warmPolicy reads each view stepPolicy uses once: the int8 bytes instead of an int8 model's fp32 matrices") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const PolicyArch arch = SmallPolicyDims::arch();
  const test::RandomPolicy p = test::makeRandomPolicy(arch, arm, 22);
  PolicyWeights<SmallPolicyDims> w =
      bindPolicyWeights<SmallPolicyDims>(p.pointers.data(), p.pointers.size(), SmallPolicyDims::arch(),
                                         Conditioning::kReference);
  auto ws = makePolicyWorkspace<SmallPolicyDims>();
  // From the manifest, by name: every tensor in fp32; the int8 model swaps the attention
  // projections and the FFN weights for their bytes (one per weight) and per-row float scales.
  std::size_t fp32 = 0, int8 = 0;
  for (const TensorSpec& t : policyManifest(arch)) {
    const std::string& n = t.name;
    const auto ends = [&n](const std::string& tail) {
      return n.size() >= tail.size() && n.compare(n.size() - tail.size(), tail.size(), tail) == 0;
    };
    const bool projection = ends(".wq") || ends(".wk") || ends(".wv") || ends(".wo");
    const bool ffn_weight = n.find(".ffn.") != std::string::npos && ends(".weight");
    const std::size_t count = t.count();
    fp32 += 4 * count;
    int8 += projection || ffn_weight ? count + 4 * static_cast<std::size_t>(t.shape[1]) : 4 * count;  // [in, out]
  }
  std::uint64_t sink = 0;
  CHECK(warmPolicy(w, *ws, sink) == fp32 + sizeof(*ws));
  CHECK(sink > 0);
  const AlignedBytes blob = quantizePolicyInt8(w);
  bindQuantizedWeights<SmallPolicyDims>(w, blob.data.get());
  CHECK(int8 < fp32 / 2);
  CHECK(warmPolicy(w, *ws, sink) == int8 + sizeof(*ws));
}
