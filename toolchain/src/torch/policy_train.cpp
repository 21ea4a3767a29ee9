#include "policy_train.hpp"

#include "nao/controller.hpp"
#include "nao/model_metadata.hpp"
#include "nao/policy.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <ostream>
#include <sstream>
#include <stdexcept>

namespace nao::tools {

LinearArCoefficients linearArCoefficients(const std::vector<LinearArModel>& models) {
  LinearArCoefficients k;
  for (const LinearArModel& m : models) {
    std::array<double, 5> c{}, beta{};
    std::array<std::array<double, 5>, kPolicyArMaxOrder> alpha{};
    for (std::size_t j = 0; j < 5; ++j) {
      c[j] = m.joints[j].c;
      beta[j] = m.joints[j].beta;
      for (std::size_t i = 0; i < m.joints[j].alpha.size(); ++i) alpha[i][j] = m.joints[j].alpha[i];
    }
    k.c.push_back(c);
    k.beta.push_back(beta);
    k.alpha.push_back(alpha);
  }
  return k;
}

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Sequences packed as doubles, one after another: demo, movement, rollout, the lengths of q,
// a_prev, r and a, worst_miss_rad, drift_rad, expert_ticks, then the four vectors' joints.
// Exact: every field is a double or a small integer.
constexpr std::size_t kPackedHead = 10;

std::size_t packedSize(const PolicySequence& s) {
  return kPackedHead + kNumJoints * (s.q.size() + s.a_prev.size() + s.r.size() + s.a.size());
}

double* pack(const PolicySequence& s, double* out) {
  const double head[kPackedHead] = {static_cast<double>(s.demo),         static_cast<double>(s.movement),
                                    static_cast<double>(s.rollout),      static_cast<double>(s.q.size()),
                                    static_cast<double>(s.a_prev.size()), static_cast<double>(s.r.size()),
                                    static_cast<double>(s.a.size()),      s.worst_miss_rad,
                                    s.drift_rad,                          static_cast<double>(s.expert_ticks)};
  out = std::copy(head, head + kPackedHead, out);
  for (const std::vector<JointVector>* v : {&s.q, &s.a_prev, &s.r, &s.a})
    for (const JointVector& x : *v) out = std::copy(x.data(), x.data() + kNumJoints, out);
  return out;
}

const double* unpack(const double* in, const double* end, PolicySequence& s) {
  if (end - in < static_cast<std::ptrdiff_t>(kPackedHead)) throw std::logic_error("gatherSequences: truncated record");
  s.demo = static_cast<int>(in[0]);
  s.movement = static_cast<int>(in[1]);
  s.rollout = static_cast<int>(in[2]);
  s.worst_miss_rad = in[7];
  s.drift_rad = in[8];
  s.expert_ticks = static_cast<std::size_t>(in[9]);
  std::vector<JointVector>* vs[4] = {&s.q, &s.a_prev, &s.r, &s.a};
  const double* x = in + kPackedHead;
  for (int k = 0; k < 4; ++k) {
    const auto n = static_cast<std::size_t>(in[3 + k]);
    if (static_cast<std::size_t>(end - x) < n * kNumJoints) throw std::logic_error("gatherSequences: truncated record");
    vs[k]->resize(n);
    for (JointVector& v : *vs[k]) {
      std::copy(x, x + kNumJoints, v.data());
      x += kNumJoints;
    }
  }
  return x;
}

}  // namespace

std::vector<PolicySequence> gatherSequences(ProcessGroup& g, std::vector<PolicySequence> mine) {
  const int w = g.worldSize();
  torch::Tensor sizes = torch::zeros({w}, torch::kInt64);
  std::int64_t my_size = 0;
  for (const PolicySequence& s : mine) my_size += static_cast<std::int64_t>(packedSize(s));
  sizes[g.rank()] = my_size;
  g.sum(sizes, "sequence sizes");
  std::vector<PolicySequence> all;
  for (int r = 0; r < w; ++r) {
    torch::Tensor buf = torch::empty({sizes[r].item<std::int64_t>()}, torch::kFloat64);
    double* const b = buf.data_ptr<double>();
    double* const e = b + buf.numel();
    if (r == g.rank()) {
      double* out = b;
      for (const PolicySequence& s : mine) out = pack(s, out);
    }
    g.broadcast(buf, r, "executed sequences");
    if (r == g.rank()) {
      for (PolicySequence& s : mine) all.push_back(std::move(s));
      continue;
    }
    for (const double* in = b; in < e;) {
      PolicySequence s;
      in = unpack(in, e, s);
      all.push_back(std::move(s));
    }
  }
  return all;
}

namespace {

// make(demos) for the listed demonstrations, in list order. With a group each rank makes a
// contiguous share and the shares are gathered (sequences of one demonstration depend on it
// alone: own seed stream, reset arm), so every rank gets what one process would make.
template <class Make>
std::vector<PolicySequence> sharedSequences(ProcessGroup* g, const std::vector<int>& demos, Make&& make) {
  if (g == nullptr) return make(demos);
  const auto [b, e] = shardRange(static_cast<std::int64_t>(demos.size()), g->worldSize(), g->rank());
  const std::vector<int> mine(demos.begin() + b, demos.begin() + e);
  return gatherSequences(*g, mine.empty() ? std::vector<PolicySequence>{} : make(mine));
}

// Executed sequences as normalised tensors (the net's norm.* buffers: the statistics it will
// carry), one entry per sequence, and how to batch them.
struct SequenceTensors {
  std::vector<torch::Tensor> qn, an, rn, target;  ///< each [T_i, J]
  std::vector<std::int64_t> movement;
  std::vector<std::int64_t> length;               ///< each sequence's demonstration's samples (phase steps)
  std::int64_t ticks = 0;                         ///< all sequences together
  std::size_t size() const { return qn.size(); }
};

SequenceTensors toTensors(const PolicyNet& net, const std::vector<PolicySequence>& seqs) {
  SequenceTensors t;
  const auto put = [](const std::vector<JointVector>& v) {
    torch::Tensor x = torch::empty({static_cast<std::int64_t>(v.size()), kNumJoints});
    auto acc = x.accessor<float, 2>();
    for (std::size_t i = 0; i < v.size(); ++i)
      for (int j = 0; j < kNumJoints; ++j) acc[static_cast<std::int64_t>(i)][j] = static_cast<float>(v[i][j]);
    return x;
  };
  for (const PolicySequence& s : seqs) {
    t.qn.push_back((put(s.q) - net->q_mean) / net->q_std);
    t.an.push_back((put(s.a_prev) - net->a_mean) / net->a_std);
    t.rn.push_back((put(s.r) - net->r_mean) / net->r_std);
    // Reference mode learns the residual of the servo inversion g·r (act() adds it back).
    const float g = net->conditioning() == Conditioning::kReference ? static_cast<float>(net->residual_gain) : 0.0f;
    torch::Tensor a = put(s.a) - g * put(s.r);
    // Autonomous mode over the linear AR base: the net learns what it misses (act() adds it back).
    if (net->conditioning() == Conditioning::kAutonomous && !net->linearAr().empty())
      a = a - net->linearArBase(put(s.q).unsqueeze(0), put(s.a_prev).unsqueeze(0),
                                torch::tensor({static_cast<std::int64_t>(s.movement)}, torch::kInt64))
                  .squeeze(0);
    t.target.push_back((a - net->a_mean) / net->a_std);
    t.movement.push_back(s.movement);
    // Phase steps count the demonstration's samples: as many ticks as nao_rt runs from its s_0.
    t.length.push_back(static_cast<std::int64_t>(s.ticks()) + 1);
    t.ticks += static_cast<std::int64_t>(s.ticks());
  }
  return t;
}

// Sequences `index` padded to the longest: inputs, targets [B,T,J] and the mask of real ticks [B,T,1].
struct Padded {
  PolicyBatch in;
  torch::Tensor target, mask;
  std::int64_t ticks = 0;  ///< real ticks
};

Padded pad(const SequenceTensors& t, const std::vector<std::size_t>& index) {
  std::int64_t longest = 0;
  for (std::size_t i : index) longest = std::max(longest, t.qn[i].size(0));
  const auto n = static_cast<std::int64_t>(index.size());
  Padded p;
  p.in.qn = torch::zeros({n, longest, kNumJoints});
  p.in.an = torch::zeros({n, longest, kNumJoints});
  p.in.rn = torch::zeros({n, longest, kNumJoints});
  p.target = torch::zeros({n, longest, kNumJoints});
  p.mask = torch::zeros({n, longest, 1});
  std::vector<std::int64_t> movement, length;
  for (std::int64_t b = 0; b < n; ++b) {
    const std::size_t i = index[static_cast<std::size_t>(b)];
    const std::int64_t len = t.qn[i].size(0);
    p.in.qn[b].slice(0, 0, len).copy_(t.qn[i]);
    p.in.an[b].slice(0, 0, len).copy_(t.an[i]);
    p.in.rn[b].slice(0, 0, len).copy_(t.rn[i]);
    p.target[b].slice(0, 0, len).copy_(t.target[i]);
    p.mask[b].slice(0, 0, len).fill_(1.0);
    movement.push_back(t.movement[i]);
    length.push_back(t.length[i]);
    p.ticks += len;
  }
  p.in.movement = torch::tensor(movement, torch::kInt64);
  p.in.length = torch::tensor(length, torch::kInt64);
  return p;
}

// Sums of the squared normalised and rad errors over sequences [begin, end), one at a time.
std::pair<double, double> errorSums(const PolicyNet& net, const SequenceTensors& t, std::size_t begin, std::size_t end) {
  torch::NoGradGuard no_grad;
  double sum_n = 0.0, sum_rad2 = 0.0;
  for (std::size_t i = begin; i < end; ++i) {
    const Padded p = pad(t, {i});
    const torch::Tensor err = net->forward(p.in) - p.target;
    sum_n += err.square().sum().item<double>();
    sum_rad2 += (err * net->a_std).square().sum().item<double>();
  }
  return {sum_n, sum_rad2};
}

// Loss over all of `t`; with a group each rank evaluates its shard and the sums are all-reduced.
SplitLoss evaluate(const PolicyNet& net, const SequenceTensors& t, ProcessGroup* group = nullptr) {
  SplitLoss loss;
  if (t.size() == 0) return loss;
  std::pair<double, double> sums;
  if (group) {
    const auto [begin, end] = shardRange(static_cast<std::int64_t>(t.size()), group->worldSize(), group->rank());
    const std::pair<double, double> mine =
        errorSums(net, t, static_cast<std::size_t>(begin), static_cast<std::size_t>(end));
    torch::Tensor both = torch::tensor({mine.first, mine.second}, torch::kFloat64);
    group->sum(both, "validation sums");
    sums = {both[0].item<double>(), both[1].item<double>()};
  } else {
    sums = errorSums(net, t, 0, t.size());
  }
  const double count = static_cast<double>(t.ticks) * kNumJoints;
  loss.normalised = sums.first / count;
  loss.mse_rad2 = sums.second / count;
  return loss;
}

std::string formatG(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string duration(double s) {
  char buf[32];
  if (s < 90)
    std::snprintf(buf, sizeof buf, "%.0f s", s);
  else if (s < 5400)
    std::snprintf(buf, sizeof buf, "%.0f min", s / 60);
  else
    std::snprintf(buf, sizeof buf, "%.1f h", s / 3600);
  return buf;
}

void check(const PolicyData& data, const TrainOptions& o) {
  const std::string problem = archProblem(o.arch);
  if (!problem.empty()) throw UserError("architecture: " + problem);
  if (o.arch.movements != data.movements())
    throw UserError("the architecture has " + std::to_string(o.arch.movements) + " movements, the data " +
                    std::to_string(data.movements()));
  if (o.arch.clusters != data.clusters())
    throw UserError("the architecture has " + std::to_string(o.arch.clusters) + " clusters, the data " +
                    std::to_string(data.clusters()));
  if (o.max_epochs < 1) throw UserError("epochs must be at least 1");
  if (o.patience < 1) throw UserError("patience must be at least 1");
  if (o.batch < 1) throw UserError("batch must be at least 1 sequence");
  if (!(o.lr > 0.0)) throw UserError("learning rate must be positive");
  if (o.dagger_rounds < 0) throw UserError("DAgger rounds must not be negative");
  if (o.dagger_rounds > 0) {
    if (o.dagger_start < 1) throw UserError("the first DAgger round must follow an epoch (start at least 1)");
    // Unsupported, not silently wrong: a checkpoint would need the rollouts.
    if (!o.resume.empty()) throw UserError("DAgger (--dagger-rounds) cannot --resume a checkpoint");
    if (!(o.execution.dagger_beta >= 0.0 && o.execution.dagger_beta < 1.0))
      throw UserError("DAgger's beta must be in [0, 1): 1 would never execute the policy");
    // The rollouts run the runtime's streaming inference, compiled for these two only.
    if (o.arch != PaperPolicyDims::arch() && o.arch != SmallPolicyDims::arch())
      throw UserError("DAgger (--dagger-rounds) needs the paper or small architecture as compiled (e.g. no --window)");
  }
  if (o.phase_ticks < 0) throw UserError("phase steps must not be negative");
  if (o.phase_ticks > 0 && o.conditioning != Conditioning::kAutonomous)
    throw UserError("phase steps (--phase-steps) are for autonomous mode (reference mode has no step embedding)");
  if (o.phase_ticks > 0 && o.dagger_rounds > 0 && o.execution.dagger_max_drift_rad > 0.0)
    throw UserError("phase steps (--phase-steps) cannot take DAgger's cut rollouts (--dagger-max-drift): their length is not the demonstration's");
  if (o.canonical_pace && o.conditioning != Conditioning::kAutonomous)
    throw UserError("a canonical pace (--canonical-pace) is for autonomous mode (reference mode follows the human's own pace)");
  if (o.canonical_pace && o.phase_ticks > 0)
    throw UserError("a canonical pace (--canonical-pace) and phase steps (--phase-steps) are two answers to one question: take one");
  if (o.select_by_rollout && o.arch != PaperPolicyDims::arch() && o.arch != SmallPolicyDims::arch())
    throw UserError("model selection on rollouts (--select rollout-dtw) needs the paper or small architecture as "
                    "compiled (e.g. no --window)");
}

static_assert(kMaxLinearArOrder == kPolicyArMaxOrder, "the runtime's AR base reads as many past actions as are fitted");


// One DAgger round: the net's current weights bound to the runtime's streaming inference (the
// policy nao_rt runs), rolled out from every listed demonstration's start (executePolicyRollouts).
template <class Dims>
std::vector<PolicySequence> rolloutsOf(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                                       const ExecutionOptions& execution, const PolicyNet& net, int round, bool labels,
                                       const std::vector<PolicySequence>& align_pool) {
  const std::vector<std::vector<float>> floats = manifestFloats(net);
  std::vector<const float*> pointers;
  for (const std::vector<float>& f : floats) pointers.push_back(f.data());
  PolicyWeights<Dims> weights = bindPolicyWeights<Dims>(pointers.data(), pointers.size(), net->conditioning());
  weights.residual_gain = static_cast<float>(net->residual_gain);
  weights.linear_ar = linearArBase<Dims::kMovements>(linearArCoefficients(net->linearAr()));
  const auto ws = makePolicyWorkspace<Dims>();
  std::size_t rollout = static_cast<std::size_t>(-1);  // which of `demos` is being rolled out
  // The step row as the controller computes it for a run as long as the demonstration (nao_rt --reference none --start I).
  ControllerParams pace;
  pace.phase_ticks = net->phase_ticks;
  const RolloutPolicy policy = [&](int movement, int t, const JointVector& q, const JointVector& a_prev,
                                   const JointVector& r) -> JointVector {
    if (t == 0) resetPolicyStream(*ws);
    PolicyInput in;
    in.q = q.cast<float>();
    in.a_prev = a_prev.cast<float>();
    in.r = r.cast<float>();  // ignored in autonomous mode
    in.movement = movement;
    if (t == 0) pace.run_ticks = static_cast<std::int64_t>(data.demos[static_cast<std::size_t>(demos[++rollout])].f.size());
    in.step = policyStep(t, pace, Dims::kMaxSteps);
    return stepPolicy(weights, *ws, in).template cast<double>();
  };
  return executePolicyRollouts(data, demos, sim, execution, policy, round, labels, align_pool);
}

// Checkpoints (torch archives): the trainable parameters in manifest order, Adam's state, the
// best weights so far, the history, and a key of everything that makes the run what it is
// except the world size, the epoch cap and the patience (those may change on resume).
std::string checkpointKey(const TrainOptions& o, std::uint64_t fingerprint) {
  std::ostringstream k;
  k.precision(17);
  k << "nao-rt checkpoint 1; data " << hex64(fingerprint) << "; config " << o.config_name << " "
    << parameterCount(o.arch) << "; " << conditioningName(o.conditioning) << "; seed " << o.seed << "; val "
    << o.val_fraction << "; batch " << o.batch << "; lr " << o.lr << "; window " << o.arch.window << "; execution "
    << o.execution.noisy_rollouts << " " << o.execution.noise_corr << " " << o.execution.expert_iterations << " "
    << o.execution.expert_tol_rad;
  for (double q : o.execution.noise_std_rad) k << " " << q;
  k << "; batches " << o.max_batches;
  if (o.conditioning == Conditioning::kReference && o.residual_gain != 0.0) k << "; residual " << o.residual_gain;
  if (o.dagger_rounds > 0) k << "; dagger " << o.dagger_rounds << " " << o.dagger_start;
  if (o.dagger_rounds > 0 && o.execution.dagger_beta > 0.0) k << " beta " << o.execution.dagger_beta;
  if (o.dagger_rounds > 0 && o.execution.dagger_max_drift_rad > 0.0) k << " max drift " << o.execution.dagger_max_drift_rad;
  if (o.dagger_rounds > 0 && o.execution.dagger_align_band > 0)
    k << " aligned " << o.execution.dagger_align_band << " return " << o.execution.dagger_return << " label "
      << static_cast<int>(o.execution.dagger_align_label);
  if (o.select_by_rollout) k << "; select rollout";
  if (o.ar_residual && o.conditioning == Conditioning::kAutonomous) k << "; ar residual";
  if (o.phase_ticks > 0) k << "; phase " << o.phase_ticks;
  if (o.canonical_pace) k << "; canonical pace " << paceMethodName(*o.canonical_pace);
  return k.str();
}

struct Checkpoint {
  std::vector<torch::Tensor> best;
  double best_val = 0.0;
  int best_epoch = 0;
  std::vector<EpochStats> history;
};

void writeCheckpoint(const std::string& path, const std::string& key, const std::vector<torch::Tensor>& params,
                     torch::optim::Adam& optimiser, const std::vector<torch::Tensor>& best, double best_val,
                     int best_epoch, const std::vector<EpochStats>& history) {
  torch::serialize::OutputArchive archive;
  archive.write("key", c10::IValue(key));
  torch::serialize::OutputArchive p, b, adam;
  for (std::size_t i = 0; i < params.size(); ++i) {
    p.write(std::to_string(i), params[i].detach());
    // No best yet only if every validation loss was NaN: the current weights stand in.
    b.write(std::to_string(i), i < best.size() ? best[i] : params[i].detach());
  }
  archive.write("params", p);
  archive.write("best", b);
  optimiser.save(adam);
  archive.write("adam", adam);
  archive.write("best_val", c10::IValue(best_val));
  archive.write("best_epoch", c10::IValue(static_cast<std::int64_t>(best_epoch)));
  torch::Tensor h = torch::empty({static_cast<std::int64_t>(history.size()), 7}, torch::kFloat64);
  for (std::size_t i = 0; i < history.size(); ++i) {
    const EpochStats& e = history[i];
    const double row[7] = {static_cast<double>(e.epoch), e.train_loss, e.val_loss, e.val_mse_rad2, e.seconds,
                           static_cast<double>(e.samples), e.rollout_dtw_m};
    for (std::int64_t c = 0; c < 7; ++c) h[static_cast<std::int64_t>(i)][c] = row[c];
  }
  archive.write("history", h);
  // Written aside and renamed: a run killed while saving leaves the previous checkpoint whole.
  const std::string tmp = path + ".tmp";
  try {
    archive.save_to(tmp);
  } catch (const std::exception& e) {
    throw UserError("cannot write the checkpoint " + tmp + ": " + e.what());
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw UserError("cannot rename " + tmp + " to " + path);
}

Checkpoint readCheckpoint(const std::string& path, const std::string& key, std::vector<torch::Tensor>& params,
                          torch::optim::Adam& optimiser) {
  Checkpoint ck;
  try {
    torch::serialize::InputArchive archive;
    archive.load_from(path);
    c10::IValue v;
    archive.read("key", v);
    if (v.toStringRef() != key)
      throw UserError("checkpoint " + path + " belongs to another run: it has '" + v.toStringRef() + "', this run '" +
                      key + "'");
    torch::serialize::InputArchive p, b, adam;
    archive.read("params", p);
    archive.read("best", b);
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < params.size(); ++i) {
      torch::Tensor t, u;
      p.read(std::to_string(i), t);
      b.read(std::to_string(i), u);
      params[i].copy_(t);
      ck.best.push_back(u);
    }
    archive.read("adam", adam);
    optimiser.load(adam);
    archive.read("best_val", v);
    ck.best_val = v.toDouble();
    archive.read("best_epoch", v);
    ck.best_epoch = static_cast<int>(v.toInt());
    torch::Tensor h;
    archive.read("history", h);
    for (std::int64_t i = 0; i < h.size(0); ++i) {
      EpochStats e;
      e.epoch = static_cast<int>(h[i][0].item<double>());
      e.train_loss = h[i][1].item<double>();
      e.val_loss = h[i][2].item<double>();
      e.val_mse_rad2 = h[i][3].item<double>();
      e.seconds = h[i][4].item<double>();
      e.samples = static_cast<std::size_t>(h[i][5].item<double>());
      if (h.size(1) > 6) e.rollout_dtw_m = h[i][6].item<double>();  // checkpoints before it: 6 columns
      ck.history.push_back(e);
    }
  } catch (const UserError&) {
    throw;
  } catch (const c10::Error& e) {
    throw UserError("cannot read the checkpoint " + path + ": " + e.what_without_backtrace());
  } catch (const std::exception& e) {
    throw UserError("cannot read the checkpoint " + path + ": " + e.what());
  }
  if (ck.history.empty() || ck.best.size() != params.size())
    throw UserError("checkpoint " + path + " holds no finished epoch");
  return ck;
}

}  // namespace

SplitLoss evaluatePolicy(const PolicyNet& net, const std::vector<PolicySequence>& sequences) {
  return evaluate(net, toTensors(net, sequences));
}

std::vector<PolicySequence> daggerRollouts(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim,
                                           const ExecutionOptions& execution, const PolicyNet& net, int round, bool labels,
                                           const std::vector<PolicySequence>& align_pool) {
  const PolicyArch& arch = net->arch();
  if (arch == PaperPolicyDims::arch())
    return rolloutsOf<PaperPolicyDims>(data, demos, sim, execution, net, round, labels, align_pool);
  if (arch == SmallPolicyDims::arch())
    return rolloutsOf<SmallPolicyDims>(data, demos, sim, execution, net, round, labels, align_pool);
  throw UserError("DAgger rollouts need the paper or small architecture as compiled");
}

namespace {

// Validation demonstrations' hand paths (f through the arm's forward kinematics), by movement.
struct ValPaths {
  std::vector<std::vector<HandPath>> by_movement;
};

ValPaths valHandPaths(const PolicyData& data, const std::vector<int>& val, const ArmModel& arm) {
  ValPaths v;
  v.by_movement.resize(static_cast<std::size_t>(data.movements()));
  for (int d : val) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    v.by_movement[static_cast<std::size_t>(demo.movement)].push_back(handPath(arm, demo.f));
  }
  return v;
}

// Per movement: the median over its validation demonstrations of the DTW to the nearest other one.
std::vector<double> nearestNeighbourDtw(const ValPaths& v) {
  std::vector<double> out;
  for (const std::vector<HandPath>& paths : v.by_movement) {
    std::vector<double> d;
    for (std::size_t i = 0; i < paths.size(); ++i) {
      const NearestDemo n = nearestDemo(paths[i], paths, static_cast<int>(i));
      if (n.index >= 0) d.push_back(n.dtw_m);
    }
    out.push_back(median(d));
  }
  return out;
}

// The net rolled out from every validation demonstration's start (executePolicyRollouts through
// the runtime's streaming inference, as nao_rt's autonomous runs), each hand path scored by its
// DTW to the nearest validation demonstration of its movement: per movement the median, and
// their mean (NaN if any is NaN: a non-finite rollout never wins).
void scoreRollouts(const PolicyData& data, const std::vector<int>& val, const SimModel& sim,
                   const ExecutionOptions& execution, const PolicyNet& net, const ValPaths& paths, EpochStats& st,
                   ProcessGroup* group) {
  const std::vector<PolicySequence> seqs = sharedSequences(
      group, val, [&](const std::vector<int>& d) { return daggerRollouts(data, d, sim, execution, net, 0, false); });
  std::vector<std::vector<double>> dtw(paths.by_movement.size());
  for (const PolicySequence& s : seqs) {
    const NearestDemo n = nearestDemo(handPath(sim.arm, s.q), paths.by_movement[static_cast<std::size_t>(s.movement)], -1);
    dtw[static_cast<std::size_t>(s.movement)].push_back(n.index >= 0 ? n.dtw_m : std::numeric_limits<double>::quiet_NaN());
  }
  st.rollout_dtw_per_movement_m.clear();
  double sum = 0.0;
  int n = 0;
  for (const std::vector<double>& d : dtw) {
    if (d.empty()) continue;
    double m = median(d);
    for (double x : d)
      if (!std::isfinite(x)) m = std::numeric_limits<double>::quiet_NaN();
    st.rollout_dtw_per_movement_m.push_back(m);
    sum += m;
    ++n;
  }
  st.rollout_dtw_m = n > 0 ? sum / n : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

double residualGain(const TrainOptions& o, const SimModel& sim) {
  if (o.conditioning != Conditioning::kReference) return 0.0;
  if (o.residual_gain >= 0.0) return o.residual_gain;
  return servoStepGain(sim.params);
}

TrainResult trainPolicy(const PolicyData& data, const SimModel& sim, const TrainOptions& o, std::ostream* progress) {
  check(data, o);
  const Clock::time_point t_start = Clock::now();
  // Determinism: one thread (no reduction-order races), deterministic kernels, seeded init.
  torch::set_num_threads(1);
  at::globalContext().setDeterministicAlgorithms(true, false);
  torch::manual_seed(o.seed);
  // Ranks > 0 say nothing: rank 0 speaks for the group.
  if (o.dist.rank != 0) progress = nullptr;

  TrainResult res;
  res.world_size = o.dist.world_size;
  res.threads_per_rank = torch::get_num_threads();
  res.fingerprint = dataFingerprint(data);
  res.split = splitByDemonstration(data, o.val_fraction, o.seed);
  if (res.split.val.empty())
    throw UserError("no validation demonstration: early stopping needs a movement with at least 2 demonstrations "
                    "and a positive validation fraction");
  // Canonical pace: the training data at one pace per movement (the rollouts are scored
  // against `data` as it is).
  PolicyData paced;
  if (o.canonical_pace) {
    res.pace_templates = paceTemplates(data, res.split.train);
    for (std::size_t m = 0; m < res.pace_templates.size(); ++m)
      if (res.pace_templates[m] < 0)
        throw UserError("--canonical-pace: movement " + data.movement_names[m] + " has no training demonstration");
    paced = pacedData(data, res.pace_templates, *o.canonical_pace);
    if (progress) {
      *progress << "canonical pace (" << paceMethodName(*o.canonical_pace) << "): every movement at the pace of its shortest training demonstration (";
      for (std::size_t m = 0; m < res.pace_templates.size(); ++m) {
        const PolicyDemo& t = data.demos[static_cast<std::size_t>(res.pace_templates[m])];
        *progress << (m ? ", " : "") << t.name << " " << t.f.size() << " ticks";
      }
      *progress << "), then held" << std::endl;
    }
  }
  const PolicyData& tdata = o.canonical_pace ? paced : data;
  // The group joins after the cheap checks and the data: a bad option fails alone, at once.
  const std::string key = checkpointKey(o, res.fingerprint);
  std::unique_ptr<ProcessGroup> group;
  if (o.dist.world_size > 1) {
    group = std::make_unique<ProcessGroup>(o.dist);
    // Ranks that disagree would call different collectives: refuse before any work.
    group->checkSame(fnv1a64(reinterpret_cast<const std::uint8_t*>(key.data()), key.size()), "options and data");
  }
  // The executed rollouts (seeded per demonstration, deterministic; each rank executes its
  // share and every rank gets all). Validation: the clean rollouts of the validation demonstrations.
  const Clock::time_point t_exec = Clock::now();
  if (progress)
    *progress << "executing the demonstrations on the simulated arm (expert labels"
              << (group ? ", " + std::to_string(o.dist.world_size) + " ranks" : std::string()) << ")" << std::endl;
  const std::vector<PolicySequence> train_seqs = sharedSequences(group.get(), res.split.train, [&](const std::vector<int>& d) {
    return executeDemos(tdata, d, sim, o.execution, o.seed, progress);
  });
  ExecutionOptions clean = o.execution;
  clean.noisy_rollouts = 0;
  const std::vector<PolicySequence> val_seqs = sharedSequences(
      group.get(), res.split.val, [&](const std::vector<int>& d) { return executeDemos(tdata, d, sim, clean, o.seed, nullptr); });
  for (const PolicySequence& s : train_seqs) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, s.worst_miss_rad);
  for (const PolicySequence& s : val_seqs) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, s.worst_miss_rad);
  res.execution_seconds = secondsSince(t_exec);
  res.train_samples = tickCount(train_seqs);
  res.val_samples = tickCount(val_seqs);
  res.train_sequences = train_seqs.size();
  res.stats = normStats(train_seqs);
  res.train_baselines = baselines(train_seqs);
  res.val_baselines = baselines(val_seqs);
  if (progress) {
    char line[200];
    std::snprintf(line, sizeof line, "%zu training rollouts (%zu ticks), %zu validation (%zu ticks) in %.0f s; expert's worst miss %.2g rad",
                  train_seqs.size(), res.train_samples, val_seqs.size(), res.val_samples, res.execution_seconds,
                  res.expert_worst_miss_rad);
    *progress << line << std::endl;
  }

  PolicyNet net(o.arch, o.conditioning);
  net->residual_gain = res.residual_gain = residualGain(o, sim);
  net->phase_ticks = o.phase_ticks;
  net->setNormalisation(res.stats);
  net->setCentroids(data.centroids);
  if (o.ar_residual && o.conditioning == Conditioning::kAutonomous) {
    // The baseline evaluate fits (training split's f, order per joint on the validation split's).
    std::vector<LinearArModel> ar;
    for (int m = 0; m < data.movements(); ++m) {
      std::vector<std::vector<JointVector>> tr, va;
      for (int d : res.split.train)
        if (tdata.demos[static_cast<std::size_t>(d)].movement == m) tr.push_back(tdata.demos[static_cast<std::size_t>(d)].f);
      for (int d : res.split.val)
        if (tdata.demos[static_cast<std::size_t>(d)].movement == m) va.push_back(tdata.demos[static_cast<std::size_t>(d)].f);
      if (tr.empty() || va.empty())
        throw UserError("--ar-residual: movement " + data.movement_names[static_cast<std::size_t>(m)] +
                        " needs training and validation demonstrations");
      ar.push_back(fitLinearAr(tr, va, kMaxLinearArOrder));
    }
    net->setLinearAr(ar);
    // The residual starts at zero: the untrained net is the baseline.
    torch::NoGradGuard no_grad;
    net->head->weight.zero_();
    net->head->bias.zero_();
  }
  SequenceTensors train = toTensors(net, train_seqs);
  const SequenceTensors train_rollouts = train;  // the final train loss: without DAgger's sequences
  const SequenceTensors val = toTensors(net, val_seqs);

  std::vector<torch::Tensor> params = net->trainableParameters();
  torch::optim::Adam optimiser(params, torch::optim::AdamOptions(o.lr));
  std::vector<torch::Tensor> best;
  double best_val = std::numeric_limits<double>::infinity();
  double epoch_seconds_sum = 0.0;
  int first_epoch = 1;
  if (!o.resume.empty()) {
    Checkpoint ck = readCheckpoint(o.resume, key, params, optimiser);
    best = std::move(ck.best);
    best_val = ck.best_val;
    res.best_epoch = ck.best_epoch;
    res.history = std::move(ck.history);
    for (const EpochStats& e : res.history) epoch_seconds_sum += e.seconds;
    first_epoch = static_cast<int>(res.history.size()) + 1;
    res.resumed_after = first_epoch - 1;
  }

  if (group) {
    // Ranks that disagree would call different collectives: refuse before the first batch.
    group->checkSame(res.train_samples, "training samples");
    group->checkInSync(params);
  }
  const int rank = o.dist.rank;
  const bool live = progress && o.live_progress;
  ValPaths val_paths;
  if (o.select_by_rollout) {
    val_paths = valHandPaths(data, res.split.val, sim.arm);
    res.val_nn_dtw_m = nearestNeighbourDtw(val_paths);
    if (first_epoch == 1) {
      // Epoch 0: the untrained net (with --ar-residual, exactly the linear AR baseline), scored
      // as the bar a trained epoch is measured against, not exported: the exported net is one
      // that learnt something (docs/policy.md).
      net->eval();
      EpochStats& st = res.epoch0;
      st.epoch = 0;
      st.train_loss = std::numeric_limits<double>::quiet_NaN();  // no training pass
      const SplitLoss v0 = evaluate(net, val, group.get());
      st.val_loss = v0.normalised;
      st.val_mse_rad2 = v0.mse_rad2;
      scoreRollouts(data, res.split.val, sim, o.execution, net, val_paths, st, group.get());
      if (progress) {
        char line[200];
        std::snprintf(line, sizeof line, "epoch 0 (before training%s)  val %.4g  rollout DTW %.1f mm", 
                      net->linearAr().empty() ? "" : ": the linear AR baseline", st.val_loss, 1e3 * st.rollout_dtw_m);
        *progress << line << std::endl;
      }
    }
  }

  const bool done_before = !res.history.empty() && (res.history.back().epoch - res.best_epoch >= o.patience ||
                                                     res.history.back().epoch >= o.max_epochs);
  for (int epoch = first_epoch; epoch <= o.max_epochs && !done_before; ++epoch) {
    const Clock::time_point t_epoch = Clock::now();
    net->train();
    // Batch order: one stream per (seed, epoch), independent of torch's generator and of the
    // world size (a global batch is the same sequences for every world size).
    const std::vector<std::size_t> order =
        shuffledIndices(train.size(), o.seed * 0x9e3779b97f4a7c15ull + static_cast<std::uint64_t>(epoch));
    const auto n_seq = static_cast<std::int64_t>(train.size());
    const std::int64_t n_batches = (n_seq + o.batch - 1) / o.batch;
    const std::int64_t n_run = o.max_batches > 0 ? std::min<std::int64_t>(n_batches, o.max_batches) : n_batches;
    double loss_sum = 0.0;
    std::int64_t seen = 0;
    Clock::time_point t_live = Clock::now();
    for (std::int64_t k = 0; k < n_run; ++k) {
      const std::int64_t b = k * o.batch, e = std::min<std::int64_t>(b + o.batch, n_seq);
      // The global batch's real ticks: every rank knows them, so each can scale its share.
      std::int64_t global_ticks = 0;
      for (std::int64_t i = b; i < e; ++i) global_ticks += train.qn[order[static_cast<std::size_t>(i)]].size(0);
      const auto [lo, hi] = group ? shardRange(e - b, o.dist.world_size, o.dist.rank) : std::pair<std::int64_t, std::int64_t>{0, e - b};
      optimiser.zero_grad();
      if (hi > lo) {
        std::vector<std::size_t> index;
        for (std::int64_t i = b + lo; i < b + hi; ++i) index.push_back(order[static_cast<std::size_t>(i)]);
        const Padded p = pad(train, index);
        // This rank's share of the global batch's mean over real ticks and joints: the all-reduced
        // sum of the gradients is the gradient of that mean.
        const torch::Tensor sse = ((net->forward(p.in) - p.target) * p.mask).square().sum();
        (sse / static_cast<double>(global_ticks * kNumJoints)).backward();
        loss_sum += sse.item<double>() / kNumJoints;
      }
      if (group) group->sumGradients(params);
      optimiser.step();
      seen += global_ticks;
      if (live && secondsSince(t_live) >= 0.5) {
        t_live = Clock::now();
        const double s = secondsSince(t_epoch);
        char line[160];
        std::snprintf(line, sizeof line, "\r\033[Kepoch %d/%d  batch %lld/%lld  %.0f ticks/s  epoch ~%s left", epoch,
                      o.max_epochs, static_cast<long long>(k + 1), static_cast<long long>(n_run), static_cast<double>(seen) / s,
                      duration(s / static_cast<double>(k + 1) * static_cast<double>(n_run - k - 1)).c_str());
        *progress << line << std::flush;
      }
    }
    if (group) {
      torch::Tensor total = torch::tensor({loss_sum}, torch::kFloat64);
      group->sum(total, "training loss");
      loss_sum = total.item<double>();
    }
    net->eval();
    EpochStats st;
    st.epoch = epoch;
    st.samples = static_cast<std::size_t>(seen);
    st.train_loss = loss_sum / static_cast<double>(seen);
    const SplitLoss v = evaluate(net, val, group.get());
    st.val_loss = v.normalised;
    st.val_mse_rad2 = v.mse_rad2;
    // Each rank rolls out its share of the validation demonstrations; all score all of them.
    const Clock::time_point t_score = Clock::now();
    if (o.select_by_rollout) scoreRollouts(data, res.split.val, sim, o.execution, net, val_paths, st, group.get());
    const double score_seconds = secondsSince(t_score);
    const double criterion = o.select_by_rollout ? st.rollout_dtw_m : st.val_loss;
    if (criterion < best_val) {
      best_val = criterion;
      res.best_epoch = epoch;
      best.clear();
      for (const torch::Tensor& p : params) best.push_back(p.detach().clone());
    }
    // Every rank applied the same summed gradients: a difference is a bug or a mixed group.
    if (group) group->checkInSync(params);
    st.seconds = secondsSince(t_epoch);
    epoch_seconds_sum += st.seconds;
    res.history.push_back(st);
    const bool stop = epoch - res.best_epoch >= o.patience || epoch == o.max_epochs;
    if (!o.checkpoint.empty() && rank == 0)
      writeCheckpoint(o.checkpoint, key, params, optimiser, best, best_val, res.best_epoch, res.history);
    if (progress) {
      char line[240];
      if (o.select_by_rollout)
        std::snprintf(line, sizeof line,
                      "%sepoch %d/%d  train %.4g  val %.4g  rollout DTW %.1f mm (best %.1f @ %d)  %.1f s (rollouts %.1f s)  %.0f samples/s  ",
                      live ? "\r\033[K" : "", epoch, o.max_epochs, st.train_loss, st.val_loss, 1e3 * st.rollout_dtw_m,
                      1e3 * best_val, res.best_epoch, st.seconds, score_seconds, static_cast<double>(st.samples) / st.seconds);
      else
        std::snprintf(line, sizeof line, "%sepoch %d/%d  train %.4g  val %.4g (best %.4g @ %d)  %.1f s  %.0f samples/s  ",
                      live ? "\r\033[K" : "", epoch, o.max_epochs, st.train_loss, st.val_loss, best_val, res.best_epoch,
                      st.seconds, static_cast<double>(st.samples) / st.seconds);
      *progress << line
                << (stop ? std::string(epoch == o.max_epochs ? "epoch cap reached" : "early stop")
                         : "~" + duration(epoch_seconds_sum / epoch * (o.max_epochs - epoch)) + " left")
                << std::endl;
    }
    if (stop) break;
    if (epoch >= o.dagger_start && epoch < o.dagger_start + o.dagger_rounds) {
      // Aggregation: the policy's own states, labelled by the expert, join the training set;
      // the norm.* buffers stay the initial rollouts' (toTensors uses the net's).
      const Clock::time_point t_round = Clock::now();
      DaggerRound dr;
      dr.after_epoch = epoch;
      const int round = static_cast<int>(res.dagger.size()) + 1;
      const std::vector<PolicySequence> seqs = sharedSequences(group.get(), res.split.train, [&](const std::vector<int>& d) {
        return daggerRollouts(tdata, d, sim, o.execution, net, round, true, train_seqs);
      });
      const SequenceTensors added = toTensors(net, seqs);
      for (std::size_t i = 0; i < added.size(); ++i) {
        train.qn.push_back(added.qn[i]);
        train.an.push_back(added.an[i]);
        train.rn.push_back(added.rn[i]);
        train.target.push_back(added.target[i]);
        train.movement.push_back(added.movement[i]);
      }
      train.ticks += added.ticks;
      dr.sequences = seqs.size();
      dr.ticks = tickCount(seqs);
      for (const PolicySequence& seq : seqs) {
        dr.drift_rad = std::max(dr.drift_rad, seq.drift_rad);
        dr.expert_ticks += seq.expert_ticks;
      }
      dr.seconds = secondsSince(t_round);
      res.dagger.push_back(dr);
      if (progress) {
        char line[200];
        std::snprintf(line, sizeof line, "DAgger round %d after epoch %d: %zu policy rollouts (%zu ticks, %zu by the expert, drift up to %.3g rad) in %.1f s",
                      round, epoch, dr.sequences, dr.ticks, dr.expert_ticks, dr.drift_rad, dr.seconds);
        *progress << line << std::endl;
      }
    }
  }

  {
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < params.size(); ++i) params[i].copy_(best[i]);
  }
  net->eval();
  res.net = net;
  res.train = evaluate(net, train_rollouts, group.get());
  res.val = evaluate(net, val, group.get());
  res.seconds = secondsSince(t_start);
  double samples = 0.0, seconds = 0.0;
  for (const EpochStats& e : res.history) {
    samples += static_cast<double>(e.samples);
    seconds += e.seconds;
  }
  res.samples_per_s = seconds > 0.0 ? samples / seconds : 0.0;
  return res;
}

std::string modelMetadata(const PolicyData& data, const TrainOptions& o, const TrainResult& r) {
  nlohmann::ordered_json j;
  j["format"] = "nao-rt policy metadata 1";
  auto& c = j["config"];
  c["name"] = o.config_name;
  c["d_model"] = o.arch.d_model;
  c["heads"] = o.arch.heads;
  c["encoder_layers"] = o.arch.encoder_layers;
  c["decoder_layers"] = o.arch.decoder_layers;
  c["ffn_hidden"] = o.arch.ffn_hidden;
  c["tokens"] = o.arch.tokens;
  c["movements"] = o.arch.movements;
  c["clusters"] = o.arch.clusters;
  c["max_steps"] = o.arch.max_steps;
  c["window"] = o.arch.window;
  c["layer_norm"] = "pre";
  c["conditioning"] = conditioningName(o.conditioning);
  auto& t = j["training"];
  t["seed"] = o.seed;
  t["max_epochs"] = o.max_epochs;
  t["patience"] = o.patience;
  t["val_fraction"] = o.val_fraction;
  t["batch"] = o.batch;
  t["optimizer"] = "adam";
  t["lr"] = o.lr;
  t["loss"] = "mse of normalised actions";
  if (r.residual_gain != 0.0) t["residual_gain"] = r.residual_gain;  // absent: none (older files)
  if (o.phase_ticks > 0) t["phase_ticks"] = o.phase_ticks;
  if (o.canonical_pace && !r.pace_templates.empty()) {
    nlohmann::json ticks = nlohmann::json::array(), names = nlohmann::json::array();
    for (int d : r.pace_templates) {
      ticks.push_back(data.demos.at(static_cast<std::size_t>(d)).f.size());
      names.push_back(data.demos.at(static_cast<std::size_t>(d)).name);
    }
    t["canonical_pace"] = {{"method", paceMethodName(*o.canonical_pace)}, {"ticks", ticks}, {"templates", names}};
  }
  // Only when they change the result: single-process files keep their bytes.
  if (o.dist.world_size > 1) t["world_size"] = o.dist.world_size;
  if (o.max_batches > 0) t["max_batches_per_epoch"] = o.max_batches;
  if (o.dagger_rounds > 0) {
    auto& dg = t["dagger"];
    dg["rounds"] = o.dagger_rounds;
    dg["start_epoch"] = o.dagger_start;
    if (o.execution.dagger_beta > 0.0) {
      dg["policy"] = "beta-mixed (each tick of round i executes the expert's command with probability beta^i; expert labels)";
      dg["beta"] = o.execution.dagger_beta;
    } else {
      dg["policy"] = "pure (the current net executes every tick; expert labels)";
    }
    if (o.execution.dagger_max_drift_rad > 0.0) dg["max_drift_rad"] = o.execution.dagger_max_drift_rad;
    if (o.execution.dagger_align_band > 0) {
      dg["align_band_ticks"] = o.execution.dagger_align_band;
      if (o.execution.dagger_align_label == ExecutionOptions::AlignLabel::kCommand) {
        dg["labels"] = "aligned command (the clean execution's command at the nearest training-demonstration point)";
      } else {
        dg["labels"] = "aligned successor (the expert toward the successor of the nearest training-demonstration point)";
        dg["return"] = o.execution.dagger_return;
      }
    }
    dg["run"] = nlohmann::ordered_json::array();
    for (const DaggerRound& x : r.dagger) {
      dg["run"].push_back({{"after_epoch", x.after_epoch}, {"sequences", x.sequences}, {"ticks", x.ticks},
                           {"drift_rad", x.drift_rad}});
      if (o.execution.dagger_beta > 0.0) dg["run"].back()["expert_ticks"] = x.expert_ticks;
    }
  }
  if (o.select_by_rollout) t["select"] = "rollout_dtw";
  if (!r.net.is_empty() && !r.net->linearAr().empty()) {
    // Per movement (index order), per joint: what nao_rt adds under the net's output.
    auto& ar = t["linear_ar"];
    ar = nlohmann::ordered_json::array();
    for (const LinearArModel& m : r.net->linearAr()) {
      nlohmann::ordered_json joints = nlohmann::ordered_json::array();
      for (const LinearArJoint& jm : m.joints)
        joints.push_back({{"order", jm.order}, {"c", jm.c}, {"beta", jm.beta}, {"alpha", jm.alpha}});
      ar.push_back(joints);
    }
  }
  t["batch_unit"] = "sequences";
  auto& ex = t["execution"];
  ex["arm"] = "simulated ODE arm of nao_rt (sim_arm), servo-lagged";
  ex["expert"] = "command ending the tick at f(t+1)";
  ex["reference_input"] = "f(t+1) - q(t), f: online blend of the snapped key poses, pole " + std::to_string(kFeatureBlendPole);
  ex["noisy_rollouts"] = o.execution.noisy_rollouts;
  ex["noise_std_rad"] = o.execution.noise_std_rad;
  ex["noise_corr"] = o.execution.noise_corr;
  ex["expert_iterations"] = o.execution.expert_iterations;
  ex["expert_tol_rad"] = o.execution.expert_tol_rad;
  auto& d = j["data"];
  d["fingerprint"] = hex64(r.fingerprint);
  // nao_rt retargets the live human the same way (runtime/app reads it back).
  d["retarget"] = data.retarget_json.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json::parse(data.retarget_json);
  d["demos"] = data.demos.size();
  d["train_samples"] = r.train_samples;
  d["val_samples"] = r.val_samples;
  j["split"]["train"] = demoNames(data, r.split.train);
  j["split"]["val"] = demoNames(data, r.split.val);
  auto& res = j["result"];
  res["epochs_run"] = r.history.size();
  res["best_epoch"] = r.best_epoch;
  res["train_loss"] = r.train.normalised;
  res["val_loss"] = r.val.normalised;
  res["train_mse_rad2"] = r.train.mse_rad2;
  res["val_mse_rad2"] = r.val.mse_rad2;
  if (o.select_by_rollout) {
    // Medians per movement (index order), m: the kept epoch's rollouts and the demonstrations'.
    const EpochStats* kept = nullptr;
    for (const EpochStats& e : r.history)
      if (e.epoch == r.best_epoch) kept = &e;
    if (kept != nullptr && !kept->rollout_dtw_per_movement_m.empty())
      res["rollout_dtw_m"] = kept->rollout_dtw_per_movement_m;
    if (r.epoch0.epoch == 0) res["epoch0_rollout_dtw_m"] = r.epoch0.rollout_dtw_per_movement_m;
    res["val_nn_dtw_m"] = r.val_nn_dtw_m;
  }
  auto& b = j["baselines_rad2"];
  b["train"]["zero_action"] = r.train_baselines.zero_action;
  b["train"]["repeat_last"] = r.train_baselines.repeat_last;
  b["val"]["zero_action"] = r.val_baselines.zero_action;
  b["val"]["repeat_last"] = r.val_baselines.repeat_last;
  return j.dump();
}

ModelHeader modelHeader(const PolicyData& data, const TrainOptions& o, const TrainResult& r,
                        const std::vector<TrainedJoint>& joints) {
  ModelHeader h;
  h.arch = o.arch;
  h.conditioning = o.conditioning;
  h.joints = joints;
  h.movement_names = data.movement_names;
  h.metadata_json = modelMetadata(data, o, r);
  return h;
}

std::string modelCard(const PolicyData& data, const TrainOptions& o, const TrainResult& r,
                      const std::string& command_line, const std::string& model_path) {
  std::ostringstream s;
  char buf[256];
  const auto ffn = [&] {
    std::string w = std::to_string(o.arch.d_model);
    for (int h : o.arch.ffn_hidden) w += "-" + std::to_string(h);
    return w + "-" + std::to_string(o.arch.d_model);
  };
  s << "# Model card: " << model_path << "\n\n";
  s << "Body-part Transformer policy (docs/policy.md), trained by `nao_toolchain train`.\n\n";
  s << "## Configuration\n\n";
  s << "| | |\n|---|---|\n";
  s << "| config | " << o.config_name << " |\n";
  s << "| conditioning | " << conditioningName(o.conditioning) << " |\n";
  s << "| d_model / heads | " << o.arch.d_model << " / " << o.arch.heads << " |\n";
  s << "| encoder / decoder layers | " << o.arch.encoder_layers << " / " << o.arch.decoder_layers << " |\n";
  s << "| FFN | " << ffn() << " (ReLU) |\n";
  s << "| layer norm | pre-LN (LN before every sub-layer, final LN on encoder memory and decoder output) |\n";
  s << "| tokens / movements / clusters / max_steps | " << o.arch.tokens << " / " << o.arch.movements << " / "
    << o.arch.clusters << " / " << o.arch.max_steps << " |\n";
  s << "| window | " << o.arch.window << " ticks (" << o.arch.window * 0.1 << " s): tokens (tick, joint), encoder causal in time, age bias |\n";
  s << "| parameters (manifest floats) | " << parameterCount(o.arch) << " |\n";
  s << "| optimiser | Adam, lr " << o.lr << ", batch " << o.batch << " sequences |\n";
  s << "| training rollouts | per demonstration 1 clean + " << o.execution.noisy_rollouts
    << " with AR(1) command noise (ρ " << o.execution.noise_corr << ", σ in {";
  for (std::size_t i = 0; i < o.execution.noise_std_rad.size(); ++i) s << (i ? ", " : "") << o.execution.noise_std_rad[i];
  s << "} rad) on the servo-lagged ODE arm; labels: the expert's command ending each tick at f(t+1) (worst miss ";
  std::snprintf(buf, sizeof buf, "%.2g rad", r.expert_worst_miss_rad);
  s << buf << "; " << r.train_sequences << " training sequences, executed in ";
  std::snprintf(buf, sizeof buf, "%.0f s", r.execution_seconds);
  s << buf << ") |\n";
  s << "| seed | " << o.seed << " |\n";
  s << "| epochs | " << r.history.size() << " run (cap " << o.max_epochs << ", patience " << o.patience
    << "), best " << r.best_epoch << " (exported) |\n";
  if (!r.net.is_empty() && !r.net->linearAr().empty()) {
    s << "| linear AR base | the net learns the residual over the per-movement, per-joint linear AR baseline "
         "(fitted on the training split's f, order on the validation split's; head initialised to zero); orders";
    for (std::size_t m = 0; m < r.net->linearAr().size(); ++m) {
      s << (m ? "; " : " ") << (m < data.movement_names.size() ? data.movement_names[m] : "?");
      for (const LinearArJoint& jm : r.net->linearAr()[m].joints) s << " " << jm.order;
    }
    s << " |\n";
  }
  if (o.canonical_pace && !r.pace_templates.empty()) {
    s << "| canonical pace | " << paceMethodName(*o.canonical_pace)
      << ": every demonstration trained on with its movement "
      << (*o.canonical_pace == PaceMethod::kDtw ? "time-warped by DTW onto" : "resampled linearly to the length of")
      << " its movement's shortest training demonstration, then held at its last pose (its length unchanged):";
    for (std::size_t m = 0; m < r.pace_templates.size(); ++m) {
      const PolicyDemo& t = data.demos.at(static_cast<std::size_t>(r.pace_templates[m]));
      s << (m ? "," : "") << " " << t.name << " (" << t.f.size() << " ticks)";
    }
    s << "; the linear AR base is fitted on the same paced trajectories; rollouts are scored against the "
         "demonstrations as they are |\n";
  }
  if (o.select_by_rollout) {
    s << "| model selection | rollout DTW: after every epoch the net (runtime streaming inference) is rolled out on "
         "the simulated arm from each validation demonstration's start; score = mean over movements of the median "
         "hand-path DTW to the nearest validation demonstration; epoch 0 (the untrained net: with the linear AR base, "
         "the baseline itself) is scored as the bar, not exported. Validation demonstrations' own nearest-neighbour "
         "DTW (median):";
    for (std::size_t m = 0; m < r.val_nn_dtw_m.size(); ++m) {
      std::snprintf(buf, sizeof buf, " %s %.1f mm", m < data.movement_names.size() ? data.movement_names[m].c_str() : "?",
                    1e3 * r.val_nn_dtw_m[m]);
      s << buf << (m + 1 < r.val_nn_dtw_m.size() ? "," : "");
    }
    s << " |\n";
  }
  if (r.resumed_after == 0) {
    std::snprintf(buf, sizeof buf, "%.1f s (%.2f s per epoch)", r.seconds,
                  r.history.empty() ? 0.0 : r.seconds / static_cast<double>(r.history.size()));
  } else {
    double epoch_s = 0.0;
    for (const EpochStats& e : r.history) epoch_s += e.seconds;
    std::snprintf(buf, sizeof buf, "%.1f s this run, resumed after epoch %d (%.2f s per epoch, all runs)", r.seconds,
                  r.resumed_after, epoch_s / static_cast<double>(r.history.size()));
  }
  s << "| wall time | " << buf << " |\n";
  s << "| parallelism | world size " << r.world_size << " (data-parallel, Gloo all-reduce), " << r.threads_per_rank
    << " thread" << (r.threads_per_rank == 1 ? "" : "s") << " per rank |\n";
  std::snprintf(buf, sizeof buf, "%.0f training samples/s, %.0f per rank (epoch wall time, validation included)",
                r.samples_per_s, r.samples_per_s / r.world_size);
  s << "| throughput | " << buf << " |\n";
  if (o.max_batches > 0) s << "| batches per epoch | capped at " << o.max_batches << " (timing run) |\n";
  if (o.dagger_rounds > 0) {
    s << "| DAgger | " << o.dagger_rounds << " round" << (o.dagger_rounds == 1 ? "" : "s") << " after epochs "
      << o.dagger_start << ".." << o.dagger_start + o.dagger_rounds - 1
      << (o.execution.dagger_beta > 0.0 ? " (beta-mixed rollouts, beta " + formatG(o.execution.dagger_beta) + "^round"
                                         : std::string(" (pure policy rollouts"));
    if (o.execution.dagger_max_drift_rad > 0.0)
      s << ", each ended where its " << (o.execution.dagger_align_band > 0 ? "distance to the aligned point" : "drift")
        << " first exceeds " << formatG(o.execution.dagger_max_drift_rad) << " rad";
    if (o.execution.dagger_align_band > 0 && o.execution.dagger_align_label == ExecutionOptions::AlignLabel::kCommand)
      s << ", labelled with the clean execution's command at the nearest training-demonstration point within "
        << o.execution.dagger_align_band << " ticks of the clock";
    else if (o.execution.dagger_align_band > 0)
      s << ", expert labels toward the nearest training-demonstration point within " << o.execution.dagger_align_band
        << " ticks of the clock, returning " << formatG(o.execution.dagger_return) << " of the offset per tick";
    else
      s << ", expert labels toward the clock's f(t+1)";
    s << ", aggregated); run:";
    if (r.dagger.empty()) s << " none";
    for (const DaggerRound& x : r.dagger) {
      std::snprintf(buf, sizeof buf, " after epoch %d +%zu sequences (%zu ticks, %zu by the expert, drift %.3g rad, %.1f s);",
                    x.after_epoch, x.sequences, x.ticks, x.expert_ticks, x.drift_rad, x.seconds);
      s << buf;
    }
    s << " |\n";
  }
  s << "\n";

  s << "## Data\n\n";
  s << "- retargeting (the clustered reference q_r, DESIGN section 5): "
    << (data.retarget_json.empty() ? std::string("not recorded by the data set") : data.retarget_json) << "\n";
  s << "- fingerprint " << hex64(r.fingerprint) << ", movements";
  for (std::size_t m = 0; m < data.movement_names.size(); ++m) s << (m ? ", " : " ") << m << " = " << data.movement_names[m];
  s << "\n- " << data.demos.size() << " demonstrations: " << r.split.train.size() << " training (" << r.train_samples
    << " samples), " << r.split.val.size() << " validation (" << r.val_samples << " samples, val fraction "
    << o.val_fraction << ")\n";
  s << "- validation demonstrations:";
  for (const std::string& n : demoNames(data, r.split.val)) s << ' ' << n;
  s << "\n\n";

  s << "## Validation MSE (rad^2, same split)\n\n";
  s << "| predictor | train | validation |\n|---|---|---|\n";
  std::snprintf(buf, sizeof buf, "| this model (epoch %d) | %.4e | %.4e |\n", r.best_epoch, r.train.mse_rad2, r.val.mse_rad2);
  s << buf;
  std::snprintf(buf, sizeof buf, "| zero action | %.4e | %.4e |\n", r.train_baselines.zero_action, r.val_baselines.zero_action);
  s << buf;
  std::snprintf(buf, sizeof buf, "| repeat last action | %.4e | %.4e |\n", r.train_baselines.repeat_last,
                r.val_baselines.repeat_last);
  s << buf << "\n";

  s << "## Per-epoch loss (normalised MSE)\n\n";
  const bool rollouts = o.select_by_rollout;
  s << "| epoch | train | val | val (rad^2) |" << (rollouts ? " rollout DTW (mm; per movement) |" : "")
    << " s | samples/s |\n|---|---|---|---|" << (rollouts ? "---|" : "") << "---|---|\n";
  std::vector<EpochStats> rows = r.history;
  if (r.epoch0.epoch == 0) rows.insert(rows.begin(), r.epoch0);
  for (const EpochStats& e : rows) {
    std::snprintf(buf, sizeof buf, "| %d%s | %.6f | %.6f | %.4e |", e.epoch, e.epoch == r.best_epoch ? " *" : "",
                  e.train_loss, e.val_loss, e.val_mse_rad2);
    s << buf;
    if (rollouts) {
      std::snprintf(buf, sizeof buf, " %.1f", 1e3 * e.rollout_dtw_m);
      s << buf;
      for (std::size_t m = 0; m < e.rollout_dtw_per_movement_m.size(); ++m) {
        std::snprintf(buf, sizeof buf, "%s%.1f", m == 0 ? " (" : " / ", 1e3 * e.rollout_dtw_per_movement_m[m]);
        s << buf;
      }
      s << (e.rollout_dtw_per_movement_m.empty() ? " |" : ") |");
    }
    std::snprintf(buf, sizeof buf, " %.1f | %.0f |\n", e.seconds,
                  e.seconds > 0.0 ? static_cast<double>(e.samples) / e.seconds : 0.0);
    s << buf;
  }
  s << "\n## Command\n\n```\n" << command_line << "\n```\n";
  if (r.world_size > 1)
    s << "\nRank 0's command: every rank R of the " << r.world_size
      << " ran the same with `--rank R` (`toolchain/nao train --procs " << r.world_size
      << "` starts them; the bytes depend on the world size, docs/training.md).\n";
  return s.str();
}

}  // namespace nao::tools
