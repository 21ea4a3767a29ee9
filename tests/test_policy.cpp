// The streaming policy forward pass (nao/policy.hpp) against an independent double-precision
// reference written here from docs/policy.md: the whole sequence at once, every layer over all
// T·J tokens with the sliding-window mask and the age bias (plain loops over the manifest
// tensors by name, row-vector convention, no Eigen, no rings), the head (a regressed chunk), the
// temporal ensemble of the last C chunks and the law; the attention ablation (body parts masked) against the same reference with those keys'
// logits −∞. Plus the properties the architecture promises: attention rows sum to 1, the decoder
// is causal across joints, the encoder causal in time with a finite receptive field, the
// conditioning inputs that must not matter do not, a reset stream repeats bitwise (the binding
// of the weights and model.bin format 3: test_policy_binding.cpp).
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "support/policy_test_model.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

using namespace nao;

namespace {

using nao::test::archOf;
using nao::test::bitwiseEqual;
using nao::test::Fixture;
using nao::test::randomInput;
using nao::test::randomModel;
using nao::test::TestModel;

float uniform(std::mt19937_64& rng, double lo, double hi) { return test::uniformFloat(rng, lo, hi); }

// ---- The reference: docs/policy.md, literally, in double, whole sequences. ----

using Tokens = std::vector<std::vector<double>>;  // [token][feature]

struct Reference {                // one tick
  std::vector<double> action;     // [J]: the executed action (ensemble + law)
  std::vector<double> net_action; // [J]: the ensemble alone
  std::vector<double> chunk;      // [J·C], entry j·C + c: this tick's a_j(t + c), rad
  std::vector<double> cross;      // [l][h][i][j], α summed over the window's ticks
  std::vector<double> score;      // [J]
  std::vector<double> mass;       // [J]
  std::vector<double> profile;    // [W]
  Tokens cross_out;               // [i][d]
};

class ReferencePolicy {
 public:
  ReferencePolicy(const TestModel& m, const PolicyArch& a) : m_(m), a_(a), d_(a.d_model), J_(a.tokens), W_(a.window) {}

  // Token (t, j) is entry t*J + j. `masked` (bit j: body part j) leaves those keys out of every
  // decoder cross-attention (their logits −∞; a query left without keys attends to nothing).
  std::vector<Reference> run(const std::vector<PolicyInput>& seq, Conditioning c, unsigned masked = 0) const {
    const int T = static_cast<int>(seq.size()), H = a_.heads;
    Tokens x(static_cast<std::size_t>(T * J_), std::vector<double>(d_)), y = x;
    const auto& w_in = t("embed.in.weight");  // [3, d]
    for (int tk = 0; tk < T; ++tk) {
      const PolicyInput& in = seq[static_cast<std::size_t>(tk)];
      const int m_idx = std::clamp(in.movement, 0, a_.movements - 1);
      const int s_idx = std::clamp(in.step, 0, a_.max_steps - 1);
      for (int j = 0; j < J_; ++j) {
        const double qn = (in.q[j] - double(t("norm.q_mean")[j])) / double(t("norm.q_std")[j]);
        const double an = (in.a_prev[j] - double(t("norm.a_mean")[j])) / double(t("norm.a_std")[j]);
        const double rn =
            c == Conditioning::kAutonomous ? 0.0 : (in.r[j] - double(t("norm.r_mean")[j])) / double(t("norm.r_std")[j]);
        std::vector<double>& xt = x[static_cast<std::size_t>(tk * J_ + j)];
        std::vector<double>& yt = y[static_cast<std::size_t>(tk * J_ + j)];
        for (int k = 0; k < d_; ++k) {
          xt[k] = qn * w_in[0 * d_ + k] + an * w_in[1 * d_ + k] + rn * w_in[2 * d_ + k] + t("embed.in.bias")[k] +
                  t("embed.joint_enc")[j * d_ + k] + t("embed.movement")[m_idx * d_ + k] + t("embed.step")[s_idx * d_ + k];
          yt[k] = an * t("embed.act.weight")[k] + t("embed.act.bias")[k] + t("embed.joint_dec")[j * d_ + k];
        }
      }
    }
    for (int l = 0; l < a_.encoder_layers; ++l) {
      const std::string p = "enc." + std::to_string(l);
      Tokens h = layerNorm(p + ".ln1", x);
      add(x, attention(p + ".attn", h, h, Mask::kWindow, nullptr, nullptr));
      add(x, ffn(p + ".ffn", layerNorm(p + ".ln2", x)));
    }
    const Tokens memory = layerNorm("enc.norm", x);
    std::vector<Reference> out(static_cast<std::size_t>(T));
    for (Reference& r : out) r.cross.assign(static_cast<std::size_t>(a_.decoder_layers * H * J_ * J_), 0.0);
    for (int l = 0; l < a_.decoder_layers; ++l) {
      const std::string p = "dec." + std::to_string(l);
      Tokens h = layerNorm(p + ".ln1", y);
      add(y, attention(p + ".self", h, h, Mask::kJointsCausal, nullptr, nullptr));
      std::vector<double> alpha;  // [h][query token][key token]
      Tokens v;
      const Tokens co = attention(p + ".cross", layerNorm(p + ".ln2", y), memory, Mask::kWindow, &alpha, &v, masked);
      const std::size_t n = static_cast<std::size_t>(T * J_);
      for (int tk = 0; tk < T; ++tk) {
        Reference& r = out[static_cast<std::size_t>(tk)];
        for (int hd = 0; hd < H; ++hd)
          for (int i = 0; i < J_; ++i)
            for (std::size_t key = 0; key < n; ++key)
              r.cross[static_cast<std::size_t>(((l * H + hd) * J_ + i) * J_) + key % J_] +=
                  alpha[(hd * n + static_cast<std::size_t>(tk * J_ + i)) * n + key];
        if (l == a_.decoder_layers - 1) {
          r.cross_out.assign(co.begin() + tk * J_, co.begin() + (tk + 1) * J_);
          record(p + ".cross", tk, T, alpha, v, r);
        }
      }
      add(y, co);
      add(y, ffn(p + ".ffn", layerNorm(p + ".ln3", y)));
    }
    const Tokens yn = layerNorm("dec.norm", y);
    for (int tk = 0; tk < T; ++tk) head(yn, tk, out[static_cast<std::size_t>(tk)]);
    ensemble(seq, c, out);
    return out;
  }

 private:
  enum class Mask { kWindow, kJointsCausal };

  // docs/policy.md "Head", normalised units, then rad: head.weight [d, C], head.bias [C] on
  // each action token.
  void head(const Tokens& yn, int tk, Reference& r) const {
    const int C = a_.chunk;
    const auto token = [&](int j) -> const std::vector<double>& { return yn[static_cast<std::size_t>(tk * J_ + j)]; };
    r.chunk.assign(static_cast<std::size_t>(J_ * C), 0.0);
    for (int j = 0; j < J_; ++j)
      for (int c = 0; c < C; ++c) {
        double v = t("head.bias")[static_cast<std::size_t>(c)];
        for (int k = 0; k < d_; ++k) v += token(j)[k] * t("head.weight")[static_cast<std::size_t>(k * C + c)];
        r.chunk[static_cast<std::size_t>(j * C + c)] = v;
      }
    for (int j = 0; j < J_; ++j)
      for (int c = 0; c < C; ++c) {
        double& v = r.chunk[static_cast<std::size_t>(j * C + c)];
        v = v * t("norm.a_std")[static_cast<std::size_t>(j)] + t("norm.a_mean")[static_cast<std::size_t>(j)];
      }
  }

  // The temporal ensemble: tick t's action takes entry k of the chunk made at t − k for every
  // k < min(t + 1, C), weighted exp(−decay·k) normalised over those k; reference mode adds the law
  // gain_j · r_j.
  void ensemble(const std::vector<PolicyInput>& seq, Conditioning c, std::vector<Reference>& out) const {
    const int C = a_.chunk, T = static_cast<int>(out.size());
    const double decay = C > 1 ? double(t("head.ensemble_decay")[0]) : 0.0;
    for (int tk = 0; tk < T; ++tk) {
      Reference& r = out[static_cast<std::size_t>(tk)];
      const int have = std::min(tk + 1, C);
      double sum = 0.0;
      for (int k = 0; k < have; ++k) sum += std::exp(-decay * k);
      r.net_action.assign(static_cast<std::size_t>(J_), 0.0);
      for (int k = 0; k < have; ++k)
        for (int j = 0; j < J_; ++j)
          r.net_action[static_cast<std::size_t>(j)] +=
              std::exp(-decay * k) / sum * out[static_cast<std::size_t>(tk - k)].chunk[static_cast<std::size_t>(j * C + k)];
      r.action = r.net_action;
      if (c == Conditioning::kReference)
        for (int j = 0; j < J_; ++j)
          r.action[static_cast<std::size_t>(j)] +=
              double(t("law.gain")[static_cast<std::size_t>(j)]) * seq[static_cast<std::size_t>(tk)].r[j];
    }
  }

  const std::vector<float>& t(const std::string& name) const { return m_[name]; }

  static void add(Tokens& x, const Tokens& dx) {
    for (std::size_t j = 0; j < x.size(); ++j)
      for (std::size_t k = 0; k < x[j].size(); ++k) x[j][k] += dx[j][k];
  }

  // x W + b, W [in, out] row-major.
  Tokens linear(const std::string& w_name, const std::string& b_name, const Tokens& x) const {
    const TensorSpec& s = m_.spec(w_name);
    const int n_in = s.shape[0], n_out = s.shape[1];
    const auto& W = t(w_name);
    const auto& b = t(b_name);
    Tokens y(x.size(), std::vector<double>(n_out));
    for (std::size_t j = 0; j < x.size(); ++j)
      for (int o = 0; o < n_out; ++o) {
        double acc = b[o];
        for (int i = 0; i < n_in; ++i) acc += x[j][i] * double(W[i * n_out + o]);
        y[j][o] = acc;
      }
    return y;
  }

  Tokens layerNorm(const std::string& p, const Tokens& x) const {
    Tokens y = x;
    for (std::size_t j = 0; j < x.size(); ++j) {
      double mean = 0.0, var = 0.0;
      for (double v : x[j]) mean += v;
      mean /= d_;
      for (double v : x[j]) var += (v - mean) * (v - mean);
      var /= d_;
      for (int k = 0; k < d_; ++k)
        y[j][k] = (x[j][k] - mean) / std::sqrt(var + 1e-5) * t(p + ".gain")[k] + t(p + ".bias")[k];
    }
    return y;
  }

  Tokens ffn(const std::string& p, const Tokens& x) const {
    Tokens h = x;
    for (int k = 0; k < 4; ++k) {
      h = linear(p + "." + std::to_string(k) + ".weight", p + "." + std::to_string(k) + ".bias", h);
      if (k < 3)
        for (auto& row : h)
          for (double& v : row) v = std::max(v, 0.0);
    }
    return h;
  }

  // MHA over all tokens of the sequence. kWindow: query (t, i) sees keys (τ, j) with
  // 0 <= t − τ < W, score + age_bias[h][t − τ]; kJointsCausal: keys of its own tick, j <= i.
  // alpha_out [h][query][key] (0 where masked), v_out = Z Wv + bv.
  // `masked` (kWindow only): keys of those body parts are left out.
  Tokens attention(const std::string& p, const Tokens& X, const Tokens& Z, Mask mask, std::vector<double>* alpha_out,
                   Tokens* v_out, unsigned masked = 0) const {
    const Tokens Q = linear(p + ".wq", p + ".bq", X), K = linear(p + ".wk", p + ".bk", Z),
                 V = linear(p + ".wv", p + ".bv", Z);
    const int H = a_.heads, dh = d_ / H;
    const std::size_t n = X.size();
    Tokens O(n, std::vector<double>(d_, 0.0));
    std::vector<double> alpha(static_cast<std::size_t>(H) * n * n, 0.0);
    for (int h = 0; h < H; ++h)
      for (std::size_t qi = 0; qi < n; ++qi) {
        const int tq = static_cast<int>(qi) / J_, iq = static_cast<int>(qi) % J_;
        std::vector<double> s(n, -INFINITY);
        double s_max = -INFINITY;
        for (std::size_t kj = 0; kj < n; ++kj) {
          const int tk = static_cast<int>(kj) / J_, jk = static_cast<int>(kj) % J_;
          const int age = tq - tk;
          double bias = 0.0;
          if (mask == Mask::kWindow) {
            if (age < 0 || age >= W_ || ((masked >> jk) & 1u) != 0) continue;
            bias = t(p + ".age_bias")[static_cast<std::size_t>(h * W_ + age)];
          } else if (age != 0 || jk > iq) {
            continue;
          }
          double dot = 0.0;
          for (int c = h * dh; c < (h + 1) * dh; ++c) dot += Q[qi][c] * K[kj][c];
          s[kj] = dot / std::sqrt(double(dh)) + bias;
          s_max = std::max(s_max, s[kj]);
        }
        if (s_max == -INFINITY) continue;  // every key masked: the query attends to nothing (O = 0)
        double sum = 0.0;
        for (std::size_t kj = 0; kj < n; ++kj) sum += std::exp(s[kj] - s_max);
        for (std::size_t kj = 0; kj < n; ++kj) {
          const double a = std::exp(s[kj] - s_max) / sum;
          alpha[(static_cast<std::size_t>(h) * n + qi) * n + kj] = a;
          for (int c = h * dh; c < (h + 1) * dh; ++c) O[qi][c] += a * V[kj][c];
        }
      }
    if (alpha_out) *alpha_out = alpha;
    if (v_out) *v_out = V;
    return linear(p + ".wo", p + ".bo", O);
  }

  // Tick tk's record: mass[j] and profile[age] (means over heads and action tokens) and the
  // norm-based score[j] = Σ_i Σ_τ ‖Σ_h α_h[(tk,i)][(τ,j)] f_h(M_(τ,j))‖, f_h(M) = V_h(M) · Wo_h.
  void record(const std::string& p, int tk, int T, const std::vector<double>& alpha, const Tokens& V,
              Reference& r) const {
    const int H = a_.heads, dh = d_ / H;
    const std::size_t n = static_cast<std::size_t>(T * J_);
    const auto& Wo = t(p + ".wo");
    r.mass.assign(static_cast<std::size_t>(J_), 0.0);
    r.profile.assign(static_cast<std::size_t>(W_), 0.0);
    r.score.assign(static_cast<std::size_t>(J_), 0.0);
    for (int h = 0; h < H; ++h)
      for (int i = 0; i < J_; ++i)
        for (std::size_t key = 0; key < n; ++key) {
          const double a = alpha[(static_cast<std::size_t>(h) * n + static_cast<std::size_t>(tk * J_ + i)) * n + key];
          const int age = tk - static_cast<int>(key) / J_;
          if (a == 0.0) continue;
          r.mass[key % J_] += a / (H * J_);
          r.profile[static_cast<std::size_t>(age)] += a / (H * J_);
        }
    for (int i = 0; i < J_; ++i)
      for (std::size_t key = 0; key < n; ++key) {
        const int age = tk - static_cast<int>(key) / J_;
        if (age < 0 || age >= W_) continue;
        double sq = 0.0;
        for (int o = 0; o < d_; ++o) {
          double v = 0.0;
          for (int h = 0; h < H; ++h) {
            double f = 0.0;
            for (int c = h * dh; c < (h + 1) * dh; ++c) f += V[key][c] * Wo[c * d_ + o];
            v += alpha[(static_cast<std::size_t>(h) * n + static_cast<std::size_t>(tk * J_ + i)) * n + key] * f;
          }
          sq += v * v;
        }
        r.score[key % J_] += std::sqrt(sq);
      }
  }

  const TestModel& m_;
  PolicyArch a_;
  int d_, J_, W_;
};

// Largest |got - want| / max(1, |want|) over a comparison, and where it was.
struct Worst {
  double err = 0.0;
  std::string where;
  void note(double got, double want, const std::string& what) {
    const double e = std::abs(got - want) / std::max(1.0, std::abs(want));
    if (!(e <= err)) {  // also catches NaN
      err = std::isnan(e) ? INFINITY : e;
      where = what + ": got " + std::to_string(got) + ", reference " + std::to_string(want);
    }
  }
};

template <class Dims>
void checkAgainstReference(const PolicyArch& arch, std::uint64_t seed, int ticks) {
  constexpr int J = Dims::kTokens, H = Dims::kHeads, LD = Dims::kDecoderLayers, D = Dims::kDModel, W = Dims::kWindow;
  const int C = arch.chunk;
  const TestModel model = randomModel(arch, seed, false);
  const std::vector<const float*> ptrs = model.pointers();
  std::mt19937_64 rng(seed + 1);
  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    const PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c);
    const auto ws = makePolicyWorkspace<Dims>();
    const ReferencePolicy ref(model, arch);
    // One rollout longer than the window (the rings wrap); steps inside and outside the table
    // (clamped by both sides).
    std::vector<PolicyInput> seq;
    const int steps[] = {0, 17, arch.max_steps - 1, arch.max_steps + 40, -5};
    for (int tk = 0; tk < ticks; ++tk) seq.push_back(randomInput(rng, 1 % arch.movements, steps[tk % 5]));
    const std::vector<Reference> r_all = ref.run(seq, c);
    resetPolicyStream(*ws);
    Worst wa, wn, wk, wc, ws_, wo, wm, wp;
    for (int tk = 0; tk < ticks; ++tk) {
      const Eigen::Matrix<float, 5, 1> action = stepPolicy(w, *ws, seq[static_cast<std::size_t>(tk)]);
      const Reference& r = r_all[static_cast<std::size_t>(tk)];
      const std::string at = "tick " + std::to_string(tk) + " ";
      for (int j = 0; j < J; ++j) wa.note(action[j], r.action[j], at + "action " + std::to_string(j));
      for (int j = 0; j < J; ++j) wn.note(ws->net_action[j], r.net_action[j], at + "net action " + std::to_string(j));
      for (int j = 0; j < J; ++j)
        for (int k = 0; k < C; ++k)
          wk.note(ws->chunk(j, k), r.chunk[static_cast<std::size_t>(j * C + k)],
                  at + "chunk(" + std::to_string(j) + ", " + std::to_string(k) + ")");
      for (int l = 0; l < LD; ++l)
        for (int h = 0; h < H; ++h)
          for (int i = 0; i < J; ++i)
            for (int j = 0; j < J; ++j)
              wc.note(ws->cross[l][h][i][j], r.cross[((l * H + h) * J + i) * J + j],
                      at + "cross[" + std::to_string(l) + "][" + std::to_string(h) + "][" + std::to_string(i) + "][" +
                          std::to_string(j) + "]");
      for (int j = 0; j < J; ++j) ws_.note(ws->score[j], r.score[j], at + "score " + std::to_string(j));
      for (int j = 0; j < J; ++j) wm.note(ws->mass[j], r.mass[j], at + "mass " + std::to_string(j));
      for (int age = 0; age < W; ++age) wp.note(ws->age_profile[age], r.profile[static_cast<std::size_t>(age)], at + "age " + std::to_string(age));
      for (int i = 0; i < J; ++i)
        for (int k = 0; k < D; ++k)
          wo.note(ws->cross_out(k, i), r.cross_out[i][k], at + "cross_out[" + std::to_string(i) + "][" + std::to_string(k) + "]");
      // The comparison is not vacuous: the actions are not all equal to one value.
      CHECK(action.maxCoeff() - action.minCoeff() > 1e-3f);
    }
    INFO(conditioningName(c), ", ", ticks, " ticks, window ", W, ", chunk ", C);
    CHECK_MESSAGE(wa.err <= 1e-5, "actions: worst ", wa.where);
    CHECK_MESSAGE(wn.err <= 1e-5, "net actions: worst ", wn.where);
    CHECK_MESSAGE(wk.err <= 1e-5, "chunks: worst ", wk.where);
    CHECK_MESSAGE(wc.err <= 1e-5, "cross α: worst ", wc.where);
    CHECK_MESSAGE(ws_.err <= 1e-5, "score: worst ", ws_.where);
    CHECK_MESSAGE(wm.err <= 1e-5, "mass: worst ", wm.where);
    CHECK_MESSAGE(wp.err <= 1e-5, "age profile: worst ", wp.where);
    CHECK_MESSAGE(wo.err <= 1e-5, "cross_out: worst ", wo.where);
    // The law: reference mode adds law.gain ⊙ r to the network's action, autonomous mode nothing.
    if (c == Conditioning::kAutonomous) CHECK(bitwiseEqual(ws->action, ws->net_action));
    if (c == Conditioning::kReference) CHECK_FALSE(bitwiseEqual(ws->action, ws->net_action));
  }
}

}  // namespace

TEST_CASE("compiled dimensions equal the runtime architectures") {
  CHECK(SmallPolicyDims::arch() == smallArch());
  CHECK(PaperPolicyDims::arch() == paperArch());
  CHECK(archProblem(PaperPolicyDims::arch()).empty());
  CHECK(PaperPolicyDims::kHeadDim == 32);
  CHECK(parameterCount(paperArch()) > 6'000'000);
}

TEST_CASE("streaming stepPolicy matches the whole-sequence double-precision reference of docs/policy.md, small dims") {
  checkAgainstReference<SmallPolicyDims>(SmallPolicyDims::arch(), 101, 3 * SmallPolicyDims::kWindow + 3);
}

TEST_CASE("streaming stepPolicy matches the whole-sequence double-precision reference of docs/policy.md, paper dims") {
  checkAgainstReference<PaperPolicyDims>(PaperPolicyDims::arch(), 202, PaperPolicyDims::kWindow + 6);
}

TEST_CASE("odd dimensions (no multiple of the packet width, a window of 3) match the reference too") {
  // d_model 36 / head dim 9 / FFN 20-13-7 exercise the kernel's leftover rows and columns; two
  // movements, four key poses, 16 step rows.
  using Odd = PolicyDims<36, 4, 1, 2, 20, 13, 7, 3>;
  checkAgainstReference<Odd>(archOf<Odd>(1, 2, 4, 16), 303, 11);
}

TEST_CASE("a regressed chunk of 5 with the temporal ensemble (decay 0.3) and the law matches the reference, small dims") {
  // Each tick's action averages the entries for it of the last 5 chunks: rollouts several
  // windows long, so the chunk ring wraps too.
  checkAgainstReference<SmallPolicyDims>(archOf<SmallPolicyDims>(5), 111, 3 * SmallPolicyDims::kWindow + 3);
}

TEST_CASE("a regressed chunk of 3 at odd dimensions (the head's dot products at d = 36) matches the reference") {
  using Odd = PolicyDims<36, 4, 1, 2, 20, 13, 7, 3>;
  checkAgainstReference<Odd>(archOf<Odd>(3, 2, 4, 16), 134, 30);
}

TEST_CASE("the encoder is causal in time with a finite receptive field: tick 0 reaches exactly the ticks within (LE + 1)(W − 1)") {
  // A change at tick 0 spreads W − 1 ticks per encoder layer and W − 1 more through the
  // cross-attention; beyond that no computation reads it, so the actions are bitwise equal.
  using Dims = SmallPolicyDims;
  constexpr int reach = (Dims::kEncoderLayers + 1) * (Dims::kWindow - 1);
  Fixture<Dims> f(71, Conditioning::kReference, false);
  std::mt19937_64 rng(72);
  std::vector<PolicyInput> seq;
  for (int tk = 0; tk < reach + 6; ++tk) seq.push_back(randomInput(rng, 1, tk));
  const auto base = f.rollout(seq);
  std::vector<PolicyInput> changed_seq = seq;
  for (int j = 0; j < 5; ++j) changed_seq[0].q[j] += 0.3f;
  const auto changed = f.rollout(changed_seq);
  for (int tk = 0; tk <= reach; ++tk)
    CHECK_MESSAGE(!bitwiseEqual(changed[static_cast<std::size_t>(tk)], base[static_cast<std::size_t>(tk)]), "tick ", tk,
                  " did not see the change at tick 0");
  for (int tk = reach + 1; tk < reach + 6; ++tk)
    CHECK_MESSAGE(bitwiseEqual(changed[static_cast<std::size_t>(tk)], base[static_cast<std::size_t>(tk)]), "tick ", tk,
                  " still depends on tick 0");
  // Ticks before a change never depend on it (causal in time).
  std::vector<PolicyInput> late = seq;
  late[10].q[2] -= 0.4f;
  const auto after = f.rollout(late);
  for (int tk = 0; tk < 10; ++tk) CHECK(bitwiseEqual(after[static_cast<std::size_t>(tk)], base[static_cast<std::size_t>(tk)]));
  CHECK_FALSE(bitwiseEqual(after[10], base[10]));
}

TEST_CASE("every cross-attention row is a distribution: α in [0, 1], rows sum to 1") {
  Fixture<PaperPolicyDims> f(11, Conditioning::kReference, false);
  std::mt19937_64 rng(12);
  double worst = 0.0;
  for (int n = 0; n < 4; ++n) {
    f.run(randomInput(rng, n % 3, n * 30));
    for (int l = 0; l < PaperPolicyDims::kDecoderLayers; ++l)
      for (int h = 0; h < PaperPolicyDims::kHeads; ++h)
        for (int i = 0; i < 5; ++i) {
          double sum = 0.0;
          for (int j = 0; j < 5; ++j) {
            const float a = f.ws->cross[l][h][i][j];
            CHECK((a >= 0.0f && a <= 1.0f));
            sum += a;
          }
          worst = std::max(worst, std::abs(sum - 1.0));
        }
  }
  CHECK_MESSAGE(worst < 1e-6, "largest |row sum - 1| = ", worst);
}

TEST_CASE("the decoder is causal: action token i does not depend on the decoder inputs of joints after i") {
  // a(t-1) also feeds the encoder (so every token), but embed.joint_dec enters only the decoder
  // input of its own joint: changing joint k's row may change actions k..4, never 0..k-1.
  Fixture<SmallPolicyDims> f(21, Conditioning::kReference, false);
  std::mt19937_64 rng(22);
  const PolicyInput in = randomInput(rng, 1, 3);
  const Eigen::Matrix<float, 5, 1> base = f.run(in);
  std::vector<float>& joint_dec = f.model["embed.joint_dec"];  // [J, d], viewed in place
  constexpr int D = SmallPolicyDims::kDModel;
  for (int k = 0; k < 5; ++k) {
    const std::vector<float> saved = joint_dec;
    // Random, not constant: layer norm removes a constant offset of a token entirely.
    for (int c = 0; c < D; ++c) joint_dec[k * D + c] += uniform(rng, -0.5, 0.5);
    const Eigen::Matrix<float, 5, 1> changed = f.run(in);
    joint_dec = saved;
    for (int i = 0; i < k; ++i)
      CHECK_MESSAGE(changed[i] == base[i], "joint ", k, "'s decoder input changed action ", i, ": ", base[i], " -> ",
                    changed[i]);
    // Not vacuous: the perturbation reaches its own token and every later one.
    for (int i = k; i < 5; ++i)
      CHECK_MESSAGE(changed[i] != base[i], "joint ", k, "'s decoder input did not reach action ", i);
  }
  CHECK(bitwiseEqual(f.run(in), base));
}

TEST_CASE("reference mode ignores the step when embed.step is zero; autonomous mode ignores r") {
  std::mt19937_64 rng(31);
  const PolicyInput in = randomInput(rng, 2, 5);
  PolicyInput other_step = in;
  other_step.step = 200;
  PolicyInput other_r = in;
  for (int j = 0; j < 5; ++j) other_r.r[j] += 0.7f;

  SUBCASE("reference mode, zero step embedding: the step changes nothing, r does") {
    Fixture<SmallPolicyDims> f(32, Conditioning::kReference, true);
    const Eigen::Matrix<float, 5, 1> a = f.run(in);
    const Eigen::Matrix<float, 5, 1> score = f.ws->score;
    CHECK(bitwiseEqual(f.run(other_step), a));
    CHECK(bitwiseEqual(f.ws->score, score));
    CHECK_FALSE(bitwiseEqual(f.run(other_r), a));
  }
  SUBCASE("autonomous mode: r changes nothing, the step does") {
    Fixture<SmallPolicyDims> f(33, Conditioning::kAutonomous, false);
    const Eigen::Matrix<float, 5, 1> a = f.run(in);
    const Eigen::Matrix<float, 5, 1> score = f.ws->score;
    CHECK(bitwiseEqual(f.run(other_r), a));
    CHECK(bitwiseEqual(f.ws->score, score));
    CHECK_FALSE(bitwiseEqual(f.run(other_step), a));
  }
}

TEST_CASE("movement and step out of range are clamped to the nearest embedding") {
  Fixture<SmallPolicyDims> f(41, Conditioning::kAutonomous, false);
  std::mt19937_64 rng(42);
  PolicyInput in = randomInput(rng, 2, 255);
  const Eigen::Matrix<float, 5, 1> last = f.run(in);
  in.movement = 9;
  in.step = 100000;
  CHECK(bitwiseEqual(f.run(in), last));
  CHECK(f.ws->movement == 2);
  CHECK(f.ws->step == 255);
  in.movement = 0;
  in.step = 0;
  const Eigen::Matrix<float, 5, 1> first = f.run(in);
  in.movement = -4;
  in.step = -1;
  CHECK(bitwiseEqual(f.run(in), first));
  CHECK_FALSE(bitwiseEqual(first, last));
}

TEST_CASE("stepPolicy is deterministic: two workspaces, a reset stream repeats bitwise, whatever ran before") {
  Fixture<PaperPolicyDims> f(51, Conditioning::kReference, false);
  const auto ws2 = makePolicyWorkspace<PaperPolicyDims>();
  std::mt19937_64 rng(52);
  std::vector<PolicyInput> seq, other_seq;
  for (int tk = 0; tk < 27; ++tk) seq.push_back(randomInput(rng, 0, tk));
  for (int tk = 0; tk < 13; ++tk) other_seq.push_back(randomInput(rng, 1, tk));
  const Eigen::Matrix<float, 5, 1> first = f.rollout(seq).back();
  const Eigen::Matrix<float, 5, 1> cross_first = f.ws->score;
  f.rollout(other_seq);  // another rollout in between (the rings start elsewhere) leaves nothing behind
  const Eigen::Matrix<float, 5, 1> again = f.rollout(seq).back();
  resetPolicyStream(*ws2);
  for (int k = 0; k < 3; ++k) stepPolicy(f.w, *ws2, other_seq[static_cast<std::size_t>(k)]);  // stale ring contents
  resetPolicyStream(*ws2);
  Eigen::Matrix<float, 5, 1> other;
  for (const PolicyInput& in : seq) other = stepPolicy(f.w, *ws2, in);
  CHECK(bitwiseEqual(again, first));
  CHECK(bitwiseEqual(other, first));
  CHECK(bitwiseEqual(ws2->score, cross_first));
  CHECK(std::memcmp(ws2->cross, f.ws->cross, sizeof(ws2->cross)) == 0);
  CHECK(std::memcmp(ws2->cross_out.data(), f.ws->cross_out.data(), sizeof(float) * ws2->cross_out.size()) == 0);
}

TEST_CASE("snapToCentroid picks the nearest key pose of the movement, ties to the lower index") {
  Fixture<SmallPolicyDims> f(61, Conditioning::kReference, false);
  std::vector<float>& c = f.model["centroids"];  // [M=3, K=10, J=5]
  const int K = f.w.clusters;
  std::mt19937_64 rng(62);
  // Brute force in double over the tensor itself.
  auto nearest = [&](int m, const Eigen::Matrix<double, 5, 1>& q) {
    int best = -1;
    double best_d = 0.0;
    for (int k = 0; k < K; ++k) {
      double d = 0.0;
      for (int j = 0; j < 5; ++j) d += std::pow(double(c[(m * K + k) * 5 + j]) - q[j], 2);
      if (best < 0 || d < best_d) {
        best = k;
        best_d = d;
      }
    }
    return best;
  };
  std::vector<int> hits(K, 0);
  for (int n = 0; n < 2000; ++n) {
    const int m = n % 3;
    Eigen::Matrix<double, 5, 1> q;
    for (int j = 0; j < 5; ++j) q[j] = uniform(rng, -1.5, 1.5);
    const int k = snapToCentroid(f.w, m, q);
    REQUIRE_MESSAGE(k == nearest(m, q), "movement ", m, " sample ", n);
    ++hits[k];
    // The float overload agrees; centroid() returns that key pose.
    CHECK(snapToCentroid(f.w, m, q.cast<float>().eval()) == nearest(m, q.cast<float>().cast<double>()));
  }
  CHECK(std::count(hits.begin(), hits.end(), 0) == 0);  // every key pose won somewhere

  const Eigen::Matrix<float, 5, 1> c27 = centroid(f.w, 2, 7);
  for (int j = 0; j < 5; ++j) CHECK(c27[j] == c[(2 * K + 7) * 5 + j]);
  CHECK(snapToCentroid(f.w, 2, c27) == 7);
  CHECK(snapToCentroid(f.w, 7, c27) == 7);  // movement clamped to 2

  // Ties: key poses 3 and 6 of movement 1 exactly 0.25 rad on either side of q, every other
  // key pose far away: the lower index wins, whichever side it is on.
  Eigen::Matrix<float, 5, 1> q = Eigen::Matrix<float, 5, 1>::Constant(0.5f);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < 5; ++j) c[(1 * K + k) * 5 + j] = 10.0f + float(k);
  for (int j = 0; j < 5; ++j) c[(1 * K + 3) * 5 + j] = c[(1 * K + 6) * 5 + j] = 0.5f;
  c[(1 * K + 3) * 5 + 2] = 0.75f;
  c[(1 * K + 6) * 5 + 2] = 0.25f;
  CHECK(snapToCentroid(f.w, 1, q) == 3);
  c[(1 * K + 3) * 5 + 2] = 0.25f;
  c[(1 * K + 6) * 5 + 2] = 0.75f;
  CHECK(snapToCentroid(f.w, 1, q) == 3);
  c[(1 * K + 6) * 5 + 2] = 0.5f;  // now 6 is strictly nearer
  CHECK(snapToCentroid(f.w, 1, q) == 6);
}

TEST_CASE("law.gain adds exactly gain ⊙ r in reference mode (same float operations) and nothing in autonomous mode; net_action is the network's share") {
  std::mt19937_64 rng(41);
  std::vector<PolicyInput> seq;
  for (int t = 0; t < 3 * SmallPolicyDims::kWindow; ++t) seq.push_back(randomInput(rng, 1, t));
  for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
    Fixture<SmallPolicyDims> plain(42, c, c == Conditioning::kReference);
    Fixture<SmallPolicyDims> law(42, c, c == Conditioning::kReference);
    std::fill(plain.model["law.gain"].begin(), plain.model["law.gain"].end(), 0.0f);  // viewed in place
    Eigen::Matrix<float, 5, 1> gain;
    for (int j = 0; j < 5; ++j) gain[j] = law.model["law.gain"][static_cast<std::size_t>(j)] = 1.0894f + 0.1f * static_cast<float>(j);
    resetPolicyStream(*plain.ws);
    resetPolicyStream(*law.ws);
    for (std::size_t t = 0; t < seq.size(); ++t) {
      const Eigen::Matrix<float, 5, 1> a0 = stepPolicy(plain.w, *plain.ws, seq[t]);
      const Eigen::Matrix<float, 5, 1> a1 = stepPolicy(law.w, *law.ws, seq[t]);
      // The network's part is untouched (the law enters after the ensemble): the whole rollout
      // stays comparable tick by tick.
      CHECK(bitwiseEqual(law.ws->net_action, plain.ws->net_action));
      CHECK(bitwiseEqual(a0, plain.ws->net_action));
      const Eigen::Matrix<float, 5, 1> expected =
          c == Conditioning::kReference ? Eigen::Matrix<float, 5, 1>(a0 + (gain.array() * seq[t].r.array()).matrix()) : a0;
      CHECK(bitwiseEqual(a1, expected));
      CHECK(bitwiseEqual(law.ws->action, a1));
    }
    if (c == Conditioning::kReference) CHECK_FALSE(bitwiseEqual(law.ws->action, law.ws->net_action));
  }
}

TEST_CASE("decodePolicyTick with body parts masked equals the reference with their keys' logits −∞ in every decoder cross-attention; masking nothing changes nothing bit for bit") {
  // Independent: the double reference leaves the masked keys out of each softmax; the runtime
  // renormalises the α it computed without them. A query left with no key (all five masked)
  // attends to nothing in both.
  using Dims = SmallPolicyDims;
  constexpr int J = 5, H = Dims::kHeads, LD = Dims::kDecoderLayers;
  const unsigned masks[] = {1u << 2, (1u << 0) | (1u << 1) | (1u << 4), 0x1eu, 0x1fu};
  for (const int chunk : {1, 3}) {
    const PolicyArch arch = archOf<Dims>(chunk);
    const TestModel model = randomModel(arch, 71 + static_cast<std::uint64_t>(chunk), false);
    const std::vector<const float*> ptrs = model.pointers();
    std::mt19937_64 rng(72);
    std::vector<PolicyInput> seq;
    for (int tk = 0; tk < 2 * Dims::kWindow + 3; ++tk) seq.push_back(randomInput(rng, 2, tk));
    for (Conditioning c : {Conditioning::kReference, Conditioning::kAutonomous}) {
      CAPTURE(chunk);
      CAPTURE(conditioningName(c));
      const PolicyWeights<Dims> w = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), arch, c);
      const ReferencePolicy ref(model, arch);
      std::vector<std::vector<Reference>> r_masked;
      for (unsigned m : masks) r_masked.push_back(ref.run(seq, c, m));
      const auto ws = makePolicyWorkspace<Dims>(), plain = makePolicyWorkspace<Dims>();
      resetPolicyStream(*ws);
      resetPolicyStream(*plain);
      Worst wk, wc;
      double masked_alpha = 0.0, moved = 0.0;
      bool same_bits = true;
      for (std::size_t tk = 0; tk < seq.size(); ++tk) {
        stepPolicy(w, *plain, seq[tk]);  // a stream that never masks
        encodePolicyTick(w, *ws, seq[tk]);
        for (std::size_t mi = 0; mi < std::size(masks); ++mi) {
          const unsigned m = masks[mi];
          decodePolicyTick(w, *ws, m);
          const Reference& r = r_masked[mi][tk];
          const std::string at = "mask " + std::to_string(m) + " tick " + std::to_string(tk) + " ";
          for (int j = 0; j < J; ++j)
            for (int k = 0; k < chunk; ++k) {
              wk.note(ws->chunk(j, k), r.chunk[static_cast<std::size_t>(j * chunk + k)], at + "chunk");
              moved = std::max(moved, std::abs(static_cast<double>(ws->chunk(j, k)) - plain->chunk(j, k)));
            }
          for (int l = 0; l < LD; ++l)
            for (int h = 0; h < H; ++h)
              for (int i = 0; i < J; ++i)
                for (int j = 0; j < J; ++j) {
                  wc.note(ws->cross[l][h][i][j], r.cross[static_cast<std::size_t>(((l * H + h) * J + i) * J + j)], at + "cross");
                  if ((m >> j) & 1u) masked_alpha = std::max(masked_alpha, static_cast<double>(ws->cross[l][h][i][j]));
                }
        }
        // Masking nothing after the probes: the step's own decoding, bit for bit.
        decodePolicyTick(w, *ws);
        commitPolicyTick(w, *ws, seq[tk]);
        same_bits = same_bits && bitwiseEqual(ws->action, plain->action) &&
                    std::memcmp(ws->chunk.data(), plain->chunk.data(), sizeof(float) * ws->chunk.size()) == 0 &&
                    std::memcmp(ws->cross, plain->cross, sizeof(ws->cross)) == 0 && bitwiseEqual(ws->score, plain->score) &&
                    bitwiseEqual(ws->mass, plain->mass) &&
                    std::memcmp(ws->cross_out.data(), plain->cross_out.data(), sizeof(float) * ws->cross_out.size()) == 0;
      }
      CHECK_MESSAGE(wk.err <= 1e-5, "masked chunk: worst ", wk.where);
      CHECK_MESSAGE(wc.err <= 1e-5, "masked cross α: worst ", wc.where);
      CHECK(masked_alpha == 0.0);  // a masked body part gets no attention at all
      CHECK(moved > 1e-4);         // and its absence changes the actions
      CHECK(same_bits);
      // decodePolicyTick(…, 0) is the step's decoding: the explicit and the default argument agree.
      const auto ws2 = makePolicyWorkspace<Dims>();
      resetPolicyStream(*ws2);
      for (std::size_t tk = 0; tk < seq.size(); ++tk) {
        encodePolicyTick(w, *ws2, seq[tk]);
        decodePolicyTick(w, *ws2, 0u);
        commitPolicyTick(w, *ws2, seq[tk]);
      }
      CHECK(bitwiseEqual(ws2->action, plain->action));
    }
  }
}

TEST_CASE("ensembledAction reads without writing: between decode and commit it is what commit stores as net_action") {
  using Dims = SmallPolicyDims;
  constexpr int C = 4;
  Fixture<Dims> f(81, Conditioning::kReference, false, archOf<Dims>(C));
  std::mt19937_64 rng(82);
  resetPolicyStream(*f.ws);
  for (int tk = 0; tk < 3 * Dims::kWindow; ++tk) {
    const PolicyInput in = randomInput(rng, 0, tk);
    encodePolicyTick(f.w, *f.ws, in);
    decodePolicyTick(f.w, *f.ws);
    const auto ring = f.ws->chunk_ring;
    const auto chunk = f.ws->chunk;
    const std::int64_t ticks = f.ws->ticks;
    const Eigen::Matrix<float, 5, 1> e1 = ensembledAction(f.w, *f.ws), e2 = ensembledAction(f.w, *f.ws);
    CHECK(bitwiseEqual(e1, e2));
    CHECK(f.ws->ticks == ticks);
    CHECK(f.ws->chunk == chunk);
    CHECK(f.ws->chunk_ring == ring);
    commitPolicyTick(f.w, *f.ws, in);
    CHECK(bitwiseEqual(f.ws->net_action, e1));
    CHECK(f.ws->ticks == ticks + 1);
    // The ring holds this tick's chunk in slot t mod C.
    CHECK(f.ws->chunk_ring[static_cast<std::size_t>(ticks % C)] == chunk);
    // From the second tick on the older chunks count: the ensemble is not this chunk's first entry.
    if (tk >= 1) CHECK_FALSE(bitwiseEqual(e1, Eigen::Matrix<float, 5, 1>(chunk.col(0))));
    if (tk == 0) CHECK(bitwiseEqual(e1, Eigen::Matrix<float, 5, 1>(chunk.col(0))));
  }
}
