#include "closed_loop.hpp"

#include "arm_copy_torch.hpp"
#include "nao/kinematics.hpp"
#include "nao/tools/arm_copy.hpp"
#include "nao/tools/evaluate.hpp"
#include "nao/tools/splitmix.hpp"
#include "policy_stream.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace nao::tools {

ClosedLoopData closedLoopData(const PolicyData& data, const RunCodeSource& codes, const SimModel& sim, double period_s,
                              double workspace_margin_rad) {
  ClosedLoopData cl;
  cl.codes = codes.codes;
  cl.code_seq = codes.sequence;
  cl.code_demo.resize(cl.codes.size());
  for (std::size_t m = 0; m < cl.codes.size(); ++m)
    for (const std::string& name : cl.codes[m].names) {
      const auto it = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& d) { return d.name == name; });
      if (it == data.demos.end()) throw std::invalid_argument("closed loop: no demonstration '" + name + "' in the data");
      cl.code_demo[m].push_back(static_cast<int>(it - data.demos.begin()));
    }
  for (const ModelWorkspace& w : demonstratedWorkspace(data))
    cl.envelope.push_back(workspace_margin_rad >= 0.0 ? widenedEnvelope(w.lo, w.hi, workspace_margin_rad) : JointEnvelope{});
  for (std::size_t m = 0; m < cl.codes.size(); ++m)
    for (std::size_t i = 0; i < cl.code_demo[m].size(); ++i) {
      const int d = cl.code_demo[m][i];
      const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
      ClosedLoopRun run = closedLoopTarget(data, cl, sim, period_s, static_cast<int>(m), demo.start,
                                           static_cast<int>(demo.f.size()), static_cast<int>(i));
      run.source = d;
      cl.own.push_back(std::move(run));
    }
  return cl;
}

int closedLoopCode(const ClosedLoopData& cl, int movement, const JointVector& start, int source) {
  const auto m = static_cast<std::size_t>(movement);
  // A movement of one training demonstration has nothing else to play: its own.
  const int code = cl.codes.at(m).size() > 1 ? runCodeIndex(cl.codes[m], start, source) : runCodeIndex(cl.codes[m], start);
  if (code < 0) throw std::invalid_argument("closed loop: a movement without training demonstrations");
  return code;
}

ClosedLoopRun closedLoopTarget(const PolicyData& data, const ClosedLoopData& cl, const SimModel& sim, double period_s,
                               int movement, const JointVector& start, int ticks, int source) {
  const auto m = static_cast<std::size_t>(movement);
  ClosedLoopRun run;
  run.movement = movement;
  run.start = clampToLimits(sim.arm, start);
  run.ticks = ticks;
  run.source_code = source;
  run.code = closedLoopCode(cl, movement, run.start, source);
  const PolicyDemo& demo = data.demos[static_cast<std::size_t>(cl.code_demo[m][static_cast<std::size_t>(run.code)])];
  std::vector<ArmCopyState> states;
  ArmCopyBackend copy(sim, &states);
  const Rollout r = trackDemoRollout(sim.arm, copy, period_s, servoStepGain(sim.params), demo.f, run.start, ticks);
  for (const ArmCopyState& st : states) {
    run.q.push_back(st.q);
    run.v.push_back(st.v);
  }
  run.a_applied = r.a_applied;
  run.hand = r.hand;
  for (int t = 0; t < ticks; ++t)
    run.f_next.push_back(clampToLimits(sim.arm, demo.f[std::min<std::size_t>(static_cast<std::size_t>(t) + 1, demo.f.size() - 1)]));
  return run;
}

std::vector<ClosedLoopStart> closedLoopStarts(const ClosedLoopData& cl, int starts, double perturb_rad,
                                              std::uint64_t seed, int epoch) {
  std::vector<ClosedLoopStart> out;
  for (const ClosedLoopRun& own : cl.own) out.push_back({own.movement, own.source, own.source_code, 0, own.start});
  for (const ClosedLoopRun& own : cl.own) {
    const auto m = static_cast<std::size_t>(own.movement);
    SplitMix64 rng(splitMix64(seed ^ splitMix64(static_cast<std::uint64_t>(epoch) * 0x100000001b3ull +
                                                static_cast<std::uint64_t>(own.source))));
    const std::size_t n = cl.codes[m].size();
    for (int k = 1; k < starts; ++k) {
      JointVector start = own.start;
      int kind = 1;
      if (k % 2 == 0 && n >= 2) {
        const JointVector& other = cl.codes[m].q[static_cast<std::size_t>(rng.below(n))];
        start += rng.uniform() * (other - own.start);
        kind = 2;
      } else {
        for (int j = 0; j < kNumJoints; ++j) start[j] += perturb_rad * rng.normal();
      }
      out.push_back({own.movement, own.source, own.source_code, kind, start});
    }
  }
  return out;
}

std::vector<ClosedLoopRun> closedLoopEpochRuns(const PolicyData& data, const ClosedLoopData& cl, const SimModel& sim,
                                               double period_s, const ClosedLoopOptions& o, std::uint64_t seed,
                                               int epoch) {
  std::vector<ClosedLoopRun> runs = cl.own;
  const std::vector<ClosedLoopStart> starts = closedLoopStarts(cl, o.starts, o.perturb_rad, seed, epoch);
  for (std::size_t i = cl.own.size(); i < starts.size(); ++i) {
    const ClosedLoopStart& st = starts[i];
    const ClosedLoopRun& own = cl.own[static_cast<std::size_t>((i - cl.own.size()) / static_cast<std::size_t>(o.starts - 1))];
    ClosedLoopRun run = closedLoopTarget(data, cl, sim, period_s, st.movement, st.start, own.ticks, st.source_code);
    run.source = st.source;
    run.kind = st.kind;
    runs.push_back(std::move(run));
  }
  return runs;
}

int closedLoopHorizon(const ClosedLoopOptions& o, int k) { return o.horizon + (k - 1) * o.horizon_growth; }

int closedLoopSegmentStart(const std::vector<const ClosedLoopRun*>& runs, int horizon, std::uint64_t key) {
  int shortest = std::numeric_limits<int>::max();
  for (const ClosedLoopRun* r : runs) shortest = std::min(shortest, r->ticks);
  if (runs.empty() || shortest <= horizon) return 0;
  return static_cast<int>(SplitMix64(key).below(static_cast<std::uint64_t>(shortest - horizon + 1)));
}

int closedLoopRunSegmentStart(const ClosedLoopRun& run, int horizon, std::uint64_t key) {
  if (run.ticks <= horizon) return 0;
  return static_cast<int>(SplitMix64(key).below(static_cast<std::uint64_t>(run.ticks - horizon + 1)));
}

ClosedLoopLoss closedLoopLoss(const PolicyNetImpl& net, RunLatentImpl* latent, const SequenceTensors& train,
                              const ClosedLoopData& cl, const SimModel& sim, double period_s,
                              const std::vector<const ClosedLoopRun*>& runs, int start_tick, int horizon,
                              const ClosedLoopOptions& o) {
  return closedLoopLoss(net, latent, train, cl, sim, period_s, runs, std::vector<int>(runs.size(), start_tick), horizon, o);
}

ClosedLoopLoss closedLoopLoss(const PolicyNetImpl& net, RunLatentImpl* latent, const SequenceTensors& train,
                              const ClosedLoopData& cl, const SimModel& sim, double period_s,
                              const std::vector<const ClosedLoopRun*>& runs, const std::vector<int>& start_ticks,
                              int horizon, const ClosedLoopOptions& o) {
  const auto n_runs = static_cast<std::int64_t>(runs.size());
  const std::int64_t J = kNumJoints;
  if (start_ticks.size() != runs.size()) throw std::invalid_argument("closed loop: one start tick per run");
  // Ticks t0 .. t0 + T − 1 are streamed with gradient, t0 the earliest segment start: each run
  // rolls its own segment (as far as it goes) and follows its target before it.
  std::int64_t t0 = std::numeric_limits<std::int64_t>::max(), end = 0;
  for (std::size_t b = 0; b < runs.size(); ++b) {
    const std::int64_t s = start_ticks[b];
    if (s < 0 || s >= runs[b]->ticks) throw std::invalid_argument("closed loop: a segment starts after a run's end");
    t0 = std::min(t0, s);
    end = std::max<std::int64_t>(end, s + std::min<std::int64_t>(horizon, runs[b]->ticks - s));
  }
  if (runs.empty()) t0 = 0;
  const std::int64_t T = end - t0;
  bool staggered = false;  // some run starts its segment after t0
  for (const int s : start_ticks) staggered = staggered || s != t0;
  // Targets after each tick [B,T,·] (held at the run's last entry past its end) and the mask of
  // each run's segment.
  torch::Tensor q_target = torch::empty({n_runs, T, J}, torch::kFloat64);
  torch::Tensor hand_target = torch::empty({n_runs, T, 3}, torch::kFloat64);
  torch::Tensor f_next = torch::empty({n_runs, T, J}, torch::kFloat64);
  torch::Tensor mask = torch::zeros({n_runs, T}, torch::kFloat64);
  // The target's states and applied actions before t0 (the warm-up), its arm state at t0.
  torch::Tensor q_before = torch::empty({n_runs, t0, J}, torch::kFloat64), a_before = torch::empty_like(q_before);
  torch::Tensor q = torch::empty({n_runs, J}, torch::kFloat64), v = torch::empty_like(q);
  torch::Tensor env_lo = torch::empty({n_runs, J}, torch::kFloat64), env_hi = torch::empty_like(env_lo);
  torch::Tensor movement = torch::empty({n_runs}, torch::kInt64);
  // Staggered segments: per tick of the streamed stretch [B,T], whether a run still follows its
  // target then (before its segment) and whether it is put in the target's state at the tick's
  // start (up to its segment's first tick), with that state and the target's applied a(t−1).
  const std::int64_t T_follow = staggered ? T : 0;
  torch::Tensor follow = torch::zeros({n_runs, T_follow}, torch::kBool), put = torch::zeros_like(follow);
  torch::Tensor q_follow = torch::zeros({n_runs, T_follow, J}, torch::kFloat64);
  torch::Tensor v_follow = torch::zeros_like(q_follow), a_follow = torch::zeros_like(q_follow);
  {
    auto fo = follow.accessor<bool, 2>(), pu = put.accessor<bool, 2>();
    auto qf = q_follow.accessor<double, 3>(), vf = v_follow.accessor<double, 3>(), af = a_follow.accessor<double, 3>();
    auto qt = q_target.accessor<double, 3>(), ht = hand_target.accessor<double, 3>(), fn = f_next.accessor<double, 3>();
    auto ma = mask.accessor<double, 2>(), qa = q.accessor<double, 2>(), va = v.accessor<double, 2>();
    auto qb = q_before.accessor<double, 3>(), ab = a_before.accessor<double, 3>();
    auto lo = env_lo.accessor<double, 2>(), hi = env_hi.accessor<double, 2>();
    for (std::int64_t b = 0; b < n_runs; ++b) {
      const ClosedLoopRun& r = *runs[static_cast<std::size_t>(b)];
      const std::int64_t s = start_ticks[static_cast<std::size_t>(b)];
      const JointEnvelope& e = cl.envelope[static_cast<std::size_t>(r.movement)];
      movement[b] = r.movement;
      for (std::int64_t j = 0; j < J; ++j) {
        qa[b][j] = r.q[static_cast<std::size_t>(t0)][j];
        va[b][j] = r.v[static_cast<std::size_t>(t0)][j];
        lo[b][j] = e.lo[j];
        hi[b][j] = e.hi[j];
      }
      for (std::int64_t t = 0; t < t0; ++t)
        for (std::int64_t j = 0; j < J; ++j) {
          qb[b][t][j] = r.q[static_cast<std::size_t>(t)][j];
          ab[b][t][j] = t > 0 ? r.a_applied[static_cast<std::size_t>(t - 1)][j] : 0.0;
        }
      for (std::int64_t t = 0; t < T; ++t) {
        const std::int64_t tick_abs = t0 + t;
        const std::size_t at = static_cast<std::size_t>(std::min<std::int64_t>(tick_abs + 1, r.ticks));
        ma[b][t] = tick_abs >= s && tick_abs < std::min<std::int64_t>(s + horizon, r.ticks) ? 1.0 : 0.0;
        const std::size_t tick = static_cast<std::size_t>(std::min<std::int64_t>(tick_abs, r.ticks - 1));
        for (std::int64_t j = 0; j < J; ++j) {
          qt[b][t][j] = r.q[at][j];
          fn[b][t][j] = r.f_next[tick][j];
        }
        for (std::int64_t k = 0; k < 3; ++k) ht[b][t][k] = r.hand[at][k];
        if (staggered && tick_abs < s) fo[b][t] = true;
        if (staggered && tick_abs <= s) {
          pu[b][t] = true;
          for (std::int64_t j = 0; j < J; ++j) {
            qf[b][t][j] = r.q[static_cast<std::size_t>(tick_abs)][j];
            vf[b][t][j] = r.v[static_cast<std::size_t>(tick_abs)][j];
            af[b][t][j] = tick_abs > 0 ? r.a_applied[static_cast<std::size_t>(tick_abs - 1)][j] : 0.0;
          }
        }
      }
    }
  }
  StreamInput in;
  in.movement = movement;
  if (latent != nullptr) {
    std::vector<std::size_t> seqs;
    for (const ClosedLoopRun* r : runs)
      seqs.push_back(cl.code_seq[static_cast<std::size_t>(r->movement)][static_cast<std::size_t>(r->code)]);
    in.z = latent->forward(pad(train, seqs), torch::zeros({n_runs, latent->dims})).z_embedded;
  }
  const torch::Tensor q_std = net.q_std.to(torch::kFloat64), a_std = net.a_std.to(torch::kFloat64);
  const double gain = servoStepGain(sim.params);
  PolicyStream stream;
  {
    // The warm-up: the target's own ticks fill the caches as a run along it would.
    torch::NoGradGuard no_grad;
    const torch::Tensor z = in.z;
    if (z.defined()) in.z = z.detach();
    for (std::int64_t t = 0; t < t0; ++t) {
      in.q = q_before.select(1, t).to(torch::kFloat32);
      in.a_prev = a_before.select(1, t).to(torch::kFloat32);
      in.step = torch::full({n_runs}, t, torch::kInt64);
      streamStep(net, stream, in);
    }
    in.z = z;
  }
  torch::Tensor a_prev = t0 > 0 ? torch::empty({n_runs, J}) : torch::zeros({n_runs, J});
  if (t0 > 0) {
    auto ap = a_prev.accessor<float, 2>();
    for (std::int64_t b = 0; b < n_runs; ++b)
      for (std::int64_t j = 0; j < J; ++j)
        ap[b][j] = static_cast<float>(runs[static_cast<std::size_t>(b)]->a_applied[static_cast<std::size_t>(t0 - 1)][j]);
  }
  ClosedLoopLoss out;
  out.loss = torch::zeros({}, torch::kFloat64);
  torch::Tensor run_hand_sse = torch::zeros({n_runs}, torch::kFloat64);
  for (std::int64_t t = 0; t < T; ++t) {
    torch::Tensor following;  // staggered: [B] the runs that still follow their target at this tick
    if (staggered) {
      following = follow.select(1, t);
      const torch::Tensor f2 = put.select(1, t).view({n_runs, 1});
      q = torch::where(f2, q_follow.select(1, t), q);
      v = torch::where(f2, v_follow.select(1, t), v);
      a_prev = torch::where(f2, a_follow.select(1, t).to(torch::kFloat32), a_prev);
    }
    in.q = q.to(torch::kFloat32);
    in.a_prev = a_prev;
    in.step = torch::full({n_runs}, t0 + t, torch::kInt64);
    const torch::Tensor a = streamStep(net, stream, in);
    if (staggered) {
      // A run that follows its target fills its caches as in the warm-up: without gradient.
      const auto detachRows = [&](torch::Tensor& x) {
        std::vector<std::int64_t> shape(static_cast<std::size_t>(x.dim()), 1);
        shape[0] = n_runs;
        x = torch::where(following.view(shape), x.detach(), x);
      };
      for (std::vector<torch::Tensor>* cache : {&stream.enc_k, &stream.enc_v, &stream.cross_k, &stream.cross_v})
        for (torch::Tensor& x : *cache) detachRows(x);
      detachRows(stream.pending);
    }
    const ArmTick tick = armCopyTick(sim, period_s, q, v, a, env_lo, env_hi);
    const torch::Tensor m = mask.select(1, t);
    // 1 per cm² of hand error and per σ² of joint error; the action the limiter cut, per a-σ².
    const torch::Tensor hand_se = (tick.hand - hand_target.select(1, t)).square().sum(1);
    const torch::Tensor q_se = ((tick.q - q_target.select(1, t)) / q_std).square().sum(1);
    const torch::Tensor a64 = a.to(torch::kFloat64);
    const torch::Tensor cut = ((a64 - tick.a_applied.detach()) / a_std).square().sum(1);
    const torch::Tensor expert = gain * (f_next.select(1, t) - q.detach());
    const torch::Tensor off = ((a64 - expert) / a_std).square().sum(1);
    out.loss = out.loss + (m * (o.hand_weight * 1e4 * hand_se + q_se + o.limit_weight * cut + o.action_weight * off)).sum();
    run_hand_sse += m * hand_se.detach();
    q = tick.q;
    v = tick.v;
    a_prev = tick.a_applied.to(torch::kFloat32);
  }
  out.ticks = static_cast<std::int64_t>(mask.sum().item<double>());
  out.hand_sse_m2 = run_hand_sse.sum().item<double>();
  for (std::int64_t b = 0; b < n_runs; ++b) out.run_hand_sse_m2.push_back(run_hand_sse[b].item<double>());
  return out;
}

}  // namespace nao::tools
