// trainPolicy: the training loop (docs/policy.md, docs/training.md).
#include "nao/controller.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/splitmix.hpp"
#include "policy_train.hpp"
#include "run_latent.hpp"
#include "train_checkpoint.hpp"
#include "train_data.hpp"
#include "train_select.hpp"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace nao::tools {
namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

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

std::string millimetresText(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f mm", 1e3 * m);
  return buf;
}

// A closed-loop epoch's hand error against its targets: all runs, then own / perturbed / between starts.
std::string closedLoopText(const EpochStats& st) {
  return " hand " + millimetresText(st.closed_loop_hand_rms_m) + " (" + millimetresText(st.closed_loop_kind_rms_m[0]) +
         " / " + millimetresText(st.closed_loop_kind_rms_m[1]) + " / " + millimetresText(st.closed_loop_kind_rms_m[2]) + ")";
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
  if (!(o.lr > 0.0)) throw UserError("learning rate must be positive");
  if (o.latent_dims < 0) throw UserError("the run latent's dimensions must not be negative (0: none)");
  if (!(o.ema_decay >= 0.0 && o.ema_decay < 1.0)) throw UserError("the moving average's decay must be in [0, 1)");
  // Reference mode's action follows the human, so a run latent would change nothing but the
  // model's key: refused.
  if (o.conditioning != Conditioning::kAutonomous && o.latent_dims > 0)
    throw UserError("a run latent (a recipe's \"run-latent\") is for autonomous mode: in reference mode the human "
                    "gives the variant");
  if (o.select_by_rollout && o.conditioning != Conditioning::kAutonomous)
    throw UserError("model selection on rollouts is for autonomous mode (a reference-mode run needs a human)");
  if (o.select_speed_vs_replay && !(o.select_by_rollout && o.latent_dims > 0))
    throw UserError("the speed against the replay is a bar of rollout selection with run codes (--select rollouts, "
                    "a recipe's \"run-latent\")");
  const ClosedLoopOptions& c = o.closed_loop;
  if (c.epochs < 0) throw UserError("closed-loop epochs must not be negative (0: none)");
  if (c.enabled()) {
    if (o.conditioning != Conditioning::kAutonomous)
      throw UserError("closed-loop training is for autonomous mode (a reference-mode run follows a human)");
    if (!(c.lr > 0.0)) throw UserError("the closed-loop learning rate must be positive");
    if (c.batch < 1) throw UserError("the closed-loop batch must be at least 1 rollout");
    if (c.horizon < 1 || c.horizon_growth < 0)
      throw UserError("the closed-loop horizon must be at least 1 tick and its growth not negative");
    if (!(c.perturb_rad >= 0.0) || !(c.grad_clip >= 0.0) || !(c.hand_weight >= 0.0) || !(c.limit_weight >= 0.0) ||
        !(c.action_weight >= 0.0))
      throw UserError("closed-loop perturbation, clip and loss weights must not be negative");
  }
  if (o.select_by_rollout && !hasRuntimeStep(o.arch))
    throw UserError("model selection on rollouts needs the runtime's step, compiled here for the paper and small "
                    "dimensions only (d_model, heads, layers, FFN, window; toolchain_dims.hpp): select by validation "
                    "loss instead");
}

// Runs carried between ranks as sequences (q and a; the rest unused).
std::vector<PolicyRun> sharedRuns(ProcessGroup* g, const std::vector<int>& demos, const PolicyData& data,
                                  const SimModel& sim, const PolicyNet& net, const std::vector<ModelRunCodes>* codes) {
  const std::vector<PolicySequence> seqs = sharedSequences(g, demos, [&](const std::vector<int>& d) {
    std::vector<PolicySequence> out;
    for (PolicyRun& r : netRuns(data, d, sim, net, codes)) {
      PolicySequence s;
      s.demo = r.demo;
      s.movement = r.movement;
      s.q = std::move(r.q);
      s.a = std::move(r.a);
      out.push_back(std::move(s));
    }
    return out;
  });
  std::vector<PolicyRun> runs;
  for (const PolicySequence& s : seqs) runs.push_back({s.demo, s.movement, s.q, s.a});
  return runs;
}

// The execution cache's file stem for this run (empty: no cache): everything the executed
// sequences depend on, hashed.
std::string executionCacheFile(const TrainOptions& o, std::uint64_t fingerprint, const PolicySplit& split) {
  if (o.execution_cache.empty()) return {};
  std::ostringstream k;
  k.precision(17);
  k << "nao-rt execution 1; data " << hex64(fingerprint) << "; " << conditioningName(o.conditioning) << "; seed "
    << o.seed << "; ";
  writeExecutionKey(k, o.execution);
  k << "; train";
  for (int d : split.train) k << " " << d;
  k << "; val";
  for (int d : split.val) k << " " << d;
  const std::string key = k.str();
  std::error_code ec;
  std::filesystem::create_directories(o.execution_cache, ec);
  if (ec) throw UserError("cannot create the execution cache " + o.execution_cache + ": " + ec.message());
  return (std::filesystem::path(o.execution_cache) /
          hex64(fnv1a64(reinterpret_cast<const std::uint8_t*>(key.data()), key.size())))
      .string();
}

// The executed demonstrations (seeded per demonstration, deterministic; each rank executes its
// share and every rank gets all): the training rollouts as the options say, the clean rollouts of
// the validation demonstrations. Fills res's execution figures, statistics and baselines.
struct Executed {
  std::vector<PolicySequence> train, val;
};

Executed executeSplit(const PolicyData& executed, const SimModel& sim, const TrainOptions& o, ProcessGroup* group,
                      TrainResult& res, std::ostream* progress) {
  const Clock::time_point t_exec = Clock::now();
  if (progress)
    *progress << "executing the demonstrations on the simulated arm (expert labels"
              << (group ? ", " + std::to_string(o.dist.world_size) + " ranks" : std::string()) << ")" << std::endl;
  ExecutionOptions clean = o.execution;
  clean.noisy_rollouts = 0;
  Executed x;
  const std::string cache = executionCacheFile(o, res.fingerprint, res.split);
  if (cache.empty() || !readSequences(cache + ".train", x.train) || !readSequences(cache + ".val", x.val)) {
    x.train = sharedSequences(group, res.split.train, [&](const std::vector<int>& d) {
      return executeDemos(executed, d, sim, o.execution, o.seed, progress);
    });
    x.val = sharedSequences(group, res.split.val, [&](const std::vector<int>& d) {
      return executeDemos(executed, d, sim, clean, o.seed, nullptr);
    });
    if (!cache.empty() && o.dist.rank == 0) {
      writeSequences(cache + ".train", x.train);
      writeSequences(cache + ".val", x.val);
    }
  } else if (progress) {
    *progress << "executed demonstrations read from " << cache << ".{train,val}" << std::endl;
  }
  for (const PolicySequence& q : x.train) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, q.worst_miss_rad);
  for (const PolicySequence& q : x.val) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, q.worst_miss_rad);
  res.execution_seconds = secondsSince(t_exec);
  res.train_samples = tickCount(x.train);
  res.val_samples = tickCount(x.val);
  res.train_sequences = x.train.size();
  res.stats = normStats(x.train);
  const double servo_gain = servoStepGain(sim.params);
  res.train_baselines = baselines(x.train, servo_gain);
  res.val_baselines = baselines(x.val, servo_gain);
  if (progress) {
    char line[200];
    std::snprintf(line, sizeof line, "%zu training rollouts (%zu ticks), %zu validation (%zu ticks) in %.0f s; expert's worst miss %.2g rad",
                  x.train.size(), res.train_samples, x.val.size(), res.val_samples, res.execution_seconds,
                  res.expert_worst_miss_rad);
    *progress << line << std::endl;
  }
  return x;
}

// A dropped input's weights stay zero, restored after every optimiser step. The runtime
// multiplies a(t-1) by those weights, so model.bin needs no other mark and nao_rt runs it
// unchanged.
void holdInputConstraints(PolicyNet& net, const TrainOptions& o) {
  if (o.previous_action) return;
  torch::NoGradGuard no_grad;
  net->embed_in->weight[1].zero_();
  net->embed_act->weight.zero_();
}

// What the loop carries from epoch to epoch.
struct TrainState {
  std::vector<torch::Tensor> params;
  std::unique_ptr<torch::optim::Adam> optimiser;
  // The moving average of the weights (a recipe's "ema"): scored, kept and written in place of the trained
  // weights, which the optimiser goes on training. The input constraints are linear, so the
  // average of constrained weights meets them too.
  std::vector<torch::Tensor> ema;
  std::int64_t ema_steps = 0;
  std::vector<torch::Tensor> best;  // the kept epoch's weights
  EpochStats best_stats;
  double epoch_seconds_sum = 0.0;
  int first_epoch = 1;

  // Trained weights <-> their moving average (nothing without one).
  void swapAverage() {
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < ema.size(); ++i) {
      torch::Tensor trained = params[i].detach().clone();
      params[i].copy_(ema[i]);
      ema[i] = trained;
    }
  }
};

// Continues from o.resume: the weights, the optimiser, the moving average, the kept epoch and the history.
void resumeFrom(const TrainOptions& o, const std::string& key, TrainState& s, TrainResult& res) {
  const std::vector<std::string> keys = {key, checkpointKey(o, res.fingerprint, true)};
  Checkpoint ck = readCheckpoint(o.resume, keys, s.params, *s.optimiser);
  if (ck.key != key && static_cast<int>(ck.history.size()) > o.max_epochs)
    throw UserError("checkpoint " + o.resume + " is past the teacher-forced epochs of another closed-loop run");
  s.best = std::move(ck.best);
  if (!s.ema.empty()) {
    if (ck.ema.size() != s.ema.size()) throw UserError("checkpoint " + o.resume + " holds no moving average");
    s.ema = std::move(ck.ema);
    s.ema_steps = ck.ema_steps;
  }
  res.best_epoch = ck.best_epoch;
  res.history = std::move(ck.history);
  for (const EpochStats& e : res.history) {
    s.epoch_seconds_sum += e.seconds;
    if (e.epoch == res.best_epoch) s.best_stats = e;
  }
  s.first_epoch = static_cast<int>(res.history.size()) + 1;
  res.resumed_after = s.first_epoch - 1;
  if (s.first_epoch > o.max_epochs + 1)  // the checkpoint's optimiser is the closed-loop one
    static_cast<torch::optim::AdamOptions&>(s.optimiser->param_groups()[0].options()).lr(o.closed_loop.lr);
}

// What an epoch reads.
struct Loop {
  const PolicyData& data;
  const SimModel& sim;
  const TrainOptions& o;
  ProcessGroup* group;
  PolicyNet& net;
  RunLatent& latent;
  const SequenceTensors& train;
  const ClosedLoopData& cl;
  double period_s;
};

// One optimiser step on the gradient of the global batch's summed loss / global_ticks (each rank
// adds its share's), then the constraints and the moving average.
void optimiserStep(const Loop& L, TrainState& s, double clip) {
  if (L.group) L.group->sumGradients(s.params);
  if (clip > 0.0) torch::nn::utils::clip_grad_norm_(s.params, clip);
  s.optimiser->step();
  holdInputConstraints(L.net, L.o);
  if (!s.ema.empty()) {
    torch::NoGradGuard no_grad;
    const double d = std::min(L.o.ema_decay, static_cast<double>(1 + s.ema_steps) / static_cast<double>(10 + s.ema_steps));
    for (std::size_t i = 0; i < s.ema.size(); ++i) s.ema[i].mul_(d).add_(s.params[i].detach(), 1.0 - d);
    ++s.ema_steps;
  }
}

// The kept epoch's weights back into the parameters.
void keepBest(TrainState& s) {
  torch::NoGradGuard no_grad;
  for (std::size_t i = 0; i < s.params.size() && i < s.best.size(); ++i) s.params[i].copy_(s.best[i]);
}

double samplesPerSecond(const std::vector<EpochStats>& history) {
  double samples = 0.0, seconds = 0.0;
  for (const EpochStats& e : history) {
    samples += static_cast<double>(e.samples);
    seconds += e.seconds;
  }
  return seconds > 0.0 ? samples / seconds : 0.0;
}

// The closed-loop phase starts from the kept teacher-forced weights with a fresh optimiser and a
// fresh moving average.
void startClosedLoop(const TrainOptions& o, TrainState& s) {
  keepBest(s);
  torch::NoGradGuard no_grad;
  s.optimiser = std::make_unique<torch::optim::Adam>(s.params, torch::optim::AdamOptions(o.closed_loop.lr));
  for (std::size_t i = 0; i < s.ema.size(); ++i) s.ema[i] = s.params[i].detach().clone();
  s.ema_steps = 0;
}

// An epoch's sums over its batches (all ranks' once summed).
struct EpochSums {
  double loss = 0.0, hand_sse = 0.0;
  std::array<double, 3> kind_sse{}, kind_ticks{};  // closed loop, per start kind
  std::int64_t seen = 0;                             // ticks
};

void sumOverRanks(ProcessGroup& g, EpochSums& e) {
  torch::Tensor total = torch::tensor({e.loss, e.hand_sse, e.kind_sse[0], e.kind_sse[1], e.kind_sse[2], e.kind_ticks[0],
                                       e.kind_ticks[1], e.kind_ticks[2]},
                                      torch::kFloat64);
  g.sum(total, "training loss");
  e.loss = total[0].item<double>();
  e.hand_sse = total[1].item<double>();
  for (std::size_t i = 0; i < 3; ++i) {
    e.kind_sse[i] = total[static_cast<std::int64_t>(2 + i)].item<double>();
    e.kind_ticks[i] = total[static_cast<std::int64_t>(5 + i)].item<double>();
  }
}

// The overwritten progress line within an epoch (a terminal only), at most twice a second.
struct LiveLine {
  std::ostream* out;  // null: none
  int epoch, last_epoch;
  Clock::time_point t_epoch, t_live;
  void operator()(std::int64_t k, std::int64_t n_run, std::int64_t seen) {
    if (out == nullptr || secondsSince(t_live) < 0.5) return;
    t_live = Clock::now();
    const double sec = secondsSince(t_epoch);
    char line[160];
    std::snprintf(line, sizeof line, "\r\033[Kepoch %d/%d  batch %lld/%lld  %.0f ticks/s  epoch ~%s left", epoch,
                  last_epoch, static_cast<long long>(k + 1), static_cast<long long>(n_run),
                  static_cast<double>(seen) / sec,
                  duration(sec / static_cast<double>(k + 1) * static_cast<double>(n_run - k - 1)).c_str());
    *out << line << std::flush;
  }
};

// A closed-loop epoch: its rollouts in a seeded order, batch by batch through the arm copy.
EpochSums closedLoopEpoch(const Loop& L, TrainState& s, int epoch, LiveLine& live) {
  const TrainOptions& o = L.o;
  EpochSums sums;
  const int k_cl = epoch - o.max_epochs;
  const std::vector<ClosedLoopRun> runs = closedLoopEpochRuns(L.data, L.cl, L.sim, L.period_s, o.closed_loop, o.seed, k_cl);
  const int horizon = closedLoopHorizon(o.closed_loop, k_cl);
  std::vector<std::size_t> order =
      shuffledIndices(runs.size(), o.seed * 0x9e3779b97f4a7c15ull + 0x5bd1e995ull * static_cast<std::uint64_t>(epoch));
  const auto n_runs = static_cast<std::int64_t>(runs.size());
  const std::int64_t B = o.closed_loop.batch;
  const std::int64_t n_batches = (n_runs + B - 1) / B;
  // Whole runs: each run's own segment start; the batches take the runs in order of it (so a
  // batch streams few ticks besides its segments), in a seeded order of batches.
  std::vector<int> run_start;
  std::vector<std::size_t> batch_order;
  if (o.closed_loop.whole_runs) {
    for (std::size_t i = 0; i < runs.size(); ++i)
      run_start.push_back(closedLoopRunSegmentStart(
          runs[i], horizon, splitMix64(o.seed ^ splitMix64(static_cast<std::uint64_t>(epoch) * 1000003ull + i))));
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return run_start[a] < run_start[b]; });
    batch_order = shuffledIndices(static_cast<std::size_t>(n_batches),
                                  o.seed * 0x9e3779b97f4a7c15ull + 0x27d4eb2full * static_cast<std::uint64_t>(epoch));
  }
  const std::int64_t n_run = o.max_batches > 0 ? std::min<std::int64_t>(n_batches, o.max_batches) : n_batches;
  for (std::int64_t k = 0; k < n_run; ++k) {
    const std::int64_t kb = batch_order.empty() ? k : static_cast<std::int64_t>(batch_order[static_cast<std::size_t>(k)]);
    const std::int64_t b = kb * B, e = std::min<std::int64_t>(b + B, n_runs);
    // The global batch's runs and where their segments start: every rank knows them.
    std::vector<const ClosedLoopRun*> batch;
    std::vector<int> starts;
    for (std::int64_t i = b; i < e; ++i) {
      batch.push_back(&runs[order[static_cast<std::size_t>(i)]]);
      if (!run_start.empty()) starts.push_back(run_start[order[static_cast<std::size_t>(i)]]);
    }
    const int t0 = run_start.empty() ? closedLoopSegmentStart(batch, horizon,
                                                              o.seed * 0x9e3779b97f4a7c15ull +
                                                                  static_cast<std::uint64_t>(epoch) * 1000003ull +
                                                                  static_cast<std::uint64_t>(k))
                                     : 0;
    if (starts.empty()) starts.assign(batch.size(), t0);
    const auto segment = [&](std::size_t i) { return std::min(horizon, batch[i]->ticks - starts[i]); };
    std::int64_t global_ticks = 0;
    for (std::size_t i = 0; i < batch.size(); ++i) global_ticks += segment(i);
    const auto [lo, hi] = L.group ? shardRange(e - b, o.dist.world_size, o.dist.rank) : std::pair<std::int64_t, std::int64_t>{0, e - b};
    s.optimiser->zero_grad();
    if (hi > lo) {
      const std::vector<const ClosedLoopRun*> mine(batch.begin() + lo, batch.begin() + hi);
      const std::vector<int> mine_starts(starts.begin() + lo, starts.begin() + hi);
      const ClosedLoopLoss l = run_start.empty()
                                   ? closedLoopLoss(*L.net, L.latent ? L.latent.get() : nullptr, L.train, L.cl, L.sim,
                                                    L.period_s, mine, t0, horizon, o.closed_loop)
                                   : closedLoopLoss(*L.net, L.latent ? L.latent.get() : nullptr, L.train, L.cl, L.sim,
                                                    L.period_s, mine, mine_starts, horizon, o.closed_loop);
      (l.loss / static_cast<double>(global_ticks)).backward();
      sums.loss += l.loss.item<double>();
      sums.hand_sse += l.hand_sse_m2;
      for (std::size_t r = 0; r < mine.size(); ++r) {
        const auto kind = static_cast<std::size_t>(mine[r]->kind);
        sums.kind_sse[kind] += l.run_hand_sse_m2[r];
        sums.kind_ticks[kind] += segment(static_cast<std::size_t>(lo) + r);
      }
    }
    optimiserStep(L, s, o.closed_loop.grad_clip);
    sums.seen += global_ticks;
    live(k, n_run, sums.seen);
  }
  return sums;
}

// A teacher-forced epoch over the executed training rollouts. Batch order: one stream per (seed,
// epoch), independent of torch's generator and of the world size (a global batch is the same
// sequences for every world size).
EpochSums teacherForcedEpoch(const Loop& L, TrainState& s, int epoch, LiveLine& live) {
  const TrainOptions& o = L.o;
  const SequenceTensors& train = L.train;
  EpochSums sums;
  const std::vector<std::size_t> order =
      shuffledIndices(train.size(), o.seed * 0x9e3779b97f4a7c15ull + static_cast<std::uint64_t>(epoch));
  const auto n_seq = static_cast<std::int64_t>(train.size());
  const std::int64_t n_batches = (n_seq + kTrainBatch - 1) / kTrainBatch;
  const std::int64_t n_run = o.max_batches > 0 ? std::min<std::int64_t>(n_batches, o.max_batches) : n_batches;
  for (std::int64_t k = 0; k < n_run; ++k) {
    const std::int64_t b = k * kTrainBatch, e = std::min<std::int64_t>(b + kTrainBatch, n_seq);
    // The global batch's real ticks: every rank knows them, so each can scale its share.
    std::int64_t global_ticks = 0;
    for (std::int64_t i = b; i < e; ++i) global_ticks += train.qn[order[static_cast<std::size_t>(i)]].size(0);
    const auto [lo, hi] = L.group ? shardRange(e - b, o.dist.world_size, o.dist.rank) : std::pair<std::int64_t, std::int64_t>{0, e - b};
    s.optimiser->zero_grad();
    if (hi > lo) {
      std::vector<std::size_t> index;
      for (std::int64_t i = b + lo; i < b + hi; ++i) index.push_back(order[static_cast<std::size_t>(i)]);
      // This rank's share of the global batch's mean over real ticks: the all-reduced sum of
      // the gradients is the gradient of that mean.
      Padded p = pad(train, index);
      torch::Tensor kl;
      if (L.latent) {
        // ε of the global batch from (seed, epoch, batch), this rank's rows: the same draws on a
        // resumed run and for every world size.
        const torch::Tensor eps =
            torch::randn({e - b, o.latent_dims},
                         at::detail::createCPUGenerator(o.seed * 0x9e3779b97f4a7c15ull +
                                                        static_cast<std::uint64_t>(epoch) * 1000003ull +
                                                        static_cast<std::uint64_t>(k)),
                         torch::kFloat32)
                .slice(0, lo, hi);
        const RunLatentImpl::Draw draw = L.latent->forward(p, eps);
        p.in.z = draw.z_embedded;
        kl = o.latent_kl * (draw.kl * p.mask.sum(1)).sum();
      }
      LossSums ls = lossSums(L.net, p);
      if (kl.defined()) ls.loss = ls.loss + kl;
      (ls.loss / static_cast<double>(global_ticks)).backward();
      sums.loss += ls.loss.item<double>();
    }
    optimiserStep(L, s, 0.0);
    sums.seen += global_ticks;
    live(k, n_run, sums.seen);
  }
  return sums;
}

// The epoch's line of progress, up to its tail (time left or why it stops).
std::string epochLine(const EpochStats& st, const EpochStats& best_stats, int best_epoch, const PolicyData& data,
                      const TrainOptions& o, bool live, int last_epoch, double score_seconds) {
  const bool closed_loop = std::isfinite(st.closed_loop_hand_rms_m);
  char line[320];
  std::string text;  // the per-movement scores have no length bound: kept out of the buffer
  const std::string phase = closed_loop ? "closed loop " : "";
  if (o.select_by_rollout) {
    std::string moves;
    for (std::size_t m = 0; m < st.rollouts.size(); ++m) {
      char part[96];
      std::snprintf(part, sizeof part, "%s%s %.1f mm x%.2f %.1f/%.1f loops", m ? ", " : "",
                    data.movement_names[m].c_str(), 1e3 * st.rollouts[m].dtw_m, st.rollouts[m].speed_ratio,
                    st.rollouts[m].loops_run, st.rollouts[m].loops_demo);
      moves += part;
      if (std::isfinite(st.rollouts[m].code_fidelity_m)) {
        std::snprintf(part, sizeof part, " plays %.1f mm", 1e3 * st.rollouts[m].code_fidelity_m);
        moves += part;
      }
    }
    std::snprintf(line, sizeof line, "%sepoch %d/%d  %strain %.4g%s  val %.4g  rollouts %.1f mm%s (",
                  live ? "\r\033[K" : "", st.epoch, last_epoch, phase.c_str(), st.train_loss,
                  closed_loop ? closedLoopText(st).c_str() : "", st.val_loss, 1e3 * st.rollout_dtw_m,
                  st.makes_movement ? " moves" : "");
    text = line + moves;
    std::snprintf(line, sizeof line, ")  best @ %d  %.1f s (rollouts %.1f s)  ", best_epoch, st.seconds, score_seconds);
    text += line;
  } else {
    std::snprintf(line, sizeof line, "%sepoch %d/%d  %strain %.4g%s  val %.4g (best %.4g @ %d)  %.1f s  %.0f samples/s  ",
                  live ? "\r\033[K" : "", st.epoch, last_epoch, phase.c_str(), st.train_loss,
                  closed_loop ? closedLoopText(st).c_str() : "", st.val_loss, best_stats.val_loss, best_epoch,
                  st.seconds, static_cast<double>(st.samples) / st.seconds);
    text = line;
  }
  return text;
}

}  // namespace

double lawGain(const TrainOptions& o, const SimModel& sim) {
  if (o.conditioning != Conditioning::kReference) return 0.0;
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
    throw UserError("no validation demonstration: model selection needs a movement with at least 2 demonstrations "
                    "and a positive validation fraction");
  // An autonomous run starts where its demonstrator did: the data it learns from do too.
  const PolicyData executed = o.conditioning == Conditioning::kAutonomous ? fromOwnStarts(data) : data;
  // The group joins after the cheap checks and the data: a bad option fails alone, at once.
  const std::string key = checkpointKey(o, res.fingerprint);
  std::unique_ptr<ProcessGroup> group;
  if (o.dist.world_size > 1) {
    group = std::make_unique<ProcessGroup>(o.dist);
    // Ranks that disagree would call different collectives: refuse before any work.
    group->checkSame(fnv1a64(reinterpret_cast<const std::uint8_t*>(key.data()), key.size()), "options and data");
  }
  const Executed x = executeSplit(executed, sim, o, group.get(), res, progress);

  PolicyNet net(o.arch, o.conditioning);
  net->setNormalisation(res.stats);
  net->setCentroids(data.centroids);
  res.law_gain = lawGain(o, sim);
  net->setLawGain(res.law_gain);
  holdInputConstraints(net, o);
  SequenceTensors train = toTensors(net, x.train);
  SequenceTensors val = toTensors(net, x.val);

  TrainState s;
  s.params = net->trainableParameters();
  RunLatent latent{nullptr};
  if (o.latent_dims > 0) {
    latent = RunLatent(o.latent_dims, o.arch.d_model);
    for (const torch::Tensor& t : latent->parameters()) s.params.push_back(t);
  }
  const double period_s = ControllerParams{}.period_s;
  // The codes a run takes at run time (model.bin's "run_codes"), scored with every epoch; the
  // closed-loop phase picks its rollouts' codes and targets from their starts and DTW tables.
  const bool on_policy = o.closed_loop.enabled();
  RunCodeSource codes;
  if (latent || on_policy) codes = runCodeSource(data, x.train, sim.arm, o.arch.d_model);
  ClosedLoopData cl;
  if (on_policy) cl = closedLoopData(data, codes, sim, period_s, ControllerParams{}.workspace_margin_rad);
  s.optimiser = std::make_unique<torch::optim::Adam>(s.params, torch::optim::AdamOptions(o.lr));
  if (o.ema_decay > 0.0)
    for (const torch::Tensor& p : s.params) s.ema.push_back(p.detach().clone());
  s.best_stats.rollout_dtw_m = std::numeric_limits<double>::quiet_NaN();
  s.best_stats.val_loss = std::numeric_limits<double>::infinity();
  const int last_epoch = o.max_epochs + o.closed_loop.epochs;
  if (!o.resume.empty()) resumeFrom(o, key, s, res);
  if (group) {
    // Ranks that disagree would call different collectives: refuse before the first batch.
    group->checkSame(res.train_samples, "training samples");
    group->checkInSync(s.params);
  }
  const bool live = progress && o.live_progress;
  SelectionReference ref;
  if (o.select_by_rollout) {
    ref = selectionReference(data, res.split.val, sim.arm, period_s, latent ? &codes.codes : nullptr);
    if (o.select_speed_vs_replay) addReplaySpeeds(ref, data, res.split.val, sim, period_s, codes.codes);
    res.val_nn_dtw_m = ref.nn_dtw_m;
  }
  // Patience counts within the closed-loop phase when there is one (the teacher-forced epochs all run).
  const auto stopsAfter = [&](int epoch) {
    if (epoch >= last_epoch) return true;
    if (!on_policy) return epoch - res.best_epoch >= o.patience;
    return epoch > o.max_epochs && epoch - std::max(res.best_epoch, o.max_epochs) >= o.patience;
  };
  const Loop L{data, sim, o, group.get(), net, latent, train, cl, period_s};

  const bool done_before = !res.history.empty() && stopsAfter(res.history.back().epoch);
  for (int epoch = s.first_epoch; epoch <= last_epoch && !done_before; ++epoch) {
    const Clock::time_point t_epoch = Clock::now();
    const bool closed_loop = epoch > o.max_epochs;
    if (closed_loop && epoch == o.max_epochs + 1) startClosedLoop(o, s);
    net->train();
    LiveLine live_line{live ? progress : nullptr, epoch, last_epoch, t_epoch, Clock::now()};
    EpochSums sums = closed_loop ? closedLoopEpoch(L, s, epoch, live_line) : teacherForcedEpoch(L, s, epoch, live_line);
    if (group) sumOverRanks(*group, sums);
    net->eval();
    s.swapAverage();  // score the average; the trained weights come back before the next epoch
    EpochStats st;
    st.epoch = epoch;
    st.samples = static_cast<std::size_t>(sums.seen);
    st.train_loss = sums.loss / static_cast<double>(sums.seen);
    if (closed_loop) {
      st.closed_loop_hand_rms_m = std::sqrt(sums.hand_sse / static_cast<double>(sums.seen));
      for (std::size_t i = 0; i < 3; ++i)
        if (sums.kind_ticks[i] > 0) st.closed_loop_kind_rms_m[i] = std::sqrt(sums.kind_sse[i] / sums.kind_ticks[i]);
    }
    const SplitLoss v = evaluateLoss(net, val, group.get());
    st.val_loss = v.loss;
    st.val_mse_rad2 = v.mse_rad2;
    const Clock::time_point t_score = Clock::now();
    // Each rank rolls out its share of the validation demonstrations; all score all of them.
    if (o.select_by_rollout) {
      if (latent) updateRunCodes(codes, train, *latent);
      scoreRuns(sharedRuns(group.get(), res.split.val, executed, sim, net, latent ? &codes.codes : nullptr), ref, sim.arm,
                period_s, st, latent ? &codes.codes : nullptr);
    }
    const double score_seconds = secondsSince(t_score);
    // A closed-loop run keeps a closed-loop epoch: its teacher-forced phase only picks the weights
    // the closed loop starts from (by the teacher-forced rule), whatever a checkpoint's history
    // recorded. A closed-loop model with run codes is trained to play its codes: kept by how
    // faithfully it does.
    const bool first_closed_loop = epoch == o.max_epochs + 1 && on_policy;
    const bool by_fidelity = epoch > o.max_epochs && latent;
    const bool better = s.best.empty() || first_closed_loop ||
                        (o.select_by_rollout ? betterEpoch(st, s.best_stats, by_fidelity) : st.val_loss < s.best_stats.val_loss);
    if (better) {
      s.best_stats = st;
      res.best_epoch = epoch;
      s.best.clear();
      for (const torch::Tensor& p : s.params) s.best.push_back(p.detach().clone());
    }
    s.swapAverage();
    // Every rank applied the same summed gradients: a difference is a bug or a mixed group.
    if (group) group->checkInSync(s.params);
    st.seconds = secondsSince(t_epoch);
    s.epoch_seconds_sum += st.seconds;
    res.history.push_back(st);
    const bool stop = stopsAfter(epoch);
    if (!o.checkpoint.empty() && o.dist.rank == 0)
      writeCheckpoint(o.checkpoint, epoch > o.max_epochs ? key : checkpointKey(o, res.fingerprint, true), s.params, *s.optimiser,
                      s.best, res.best_epoch, res.history, s.ema, s.ema_steps);
    if (progress)
      *progress << epochLine(st, s.best_stats, res.best_epoch, data, o, live, last_epoch, score_seconds)
                << (stop ? std::string(epoch == last_epoch ? "epoch cap reached" : "early stop")
                         : "~" + duration(s.epoch_seconds_sum / (epoch - s.first_epoch + 1) * (last_epoch - epoch)) +
                               " left")
                << std::endl;
    if (stop) break;
  }

  keepBest(s);
  net->eval();
  res.net = net;
  if (latent) {
    updateRunCodes(codes, train, *latent);
    res.run_codes = std::move(codes.codes);
  }
  res.train = evaluateLoss(net, train, group.get());
  res.val = evaluateLoss(net, val, group.get());
  res.seconds = secondsSince(t_start);
  res.samples_per_s = samplesPerSecond(res.history);
  return res;
}

}  // namespace nao::tools
