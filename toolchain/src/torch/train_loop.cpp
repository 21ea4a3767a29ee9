// trainPolicy: the training loop (docs/policy.md, docs/training.md).
#include "nao/controller.hpp"
#include "nao/tools/command.hpp"
#include "policy_train.hpp"
#include "run_latent.hpp"
#include "train_checkpoint.hpp"
#include "train_data.hpp"
#include "train_select.hpp"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>

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
    throw UserError("a run latent (--run-latent) is for autonomous mode: in reference mode the human gives the variant");
  if (o.select_by_rollout && o.conditioning != Conditioning::kAutonomous)
    throw UserError("model selection on rollouts is for autonomous mode (a reference-mode run needs a human)");
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
  // The executed rollouts (seeded per demonstration, deterministic; each rank executes its share
  // and every rank gets all). Validation: the clean rollouts of the validation demonstrations.
  const Clock::time_point t_exec = Clock::now();
  if (progress)
    *progress << "executing the demonstrations on the simulated arm (expert labels"
              << (group ? ", " + std::to_string(o.dist.world_size) + " ranks" : std::string()) << ")" << std::endl;
  ExecutionOptions clean = o.execution;
  clean.noisy_rollouts = 0;
  std::vector<PolicySequence> train_seqs, val_seqs;
  const std::string cache = executionCacheFile(o, res.fingerprint, res.split);
  if (cache.empty() || !readSequences(cache + ".train", train_seqs) || !readSequences(cache + ".val", val_seqs)) {
    train_seqs = sharedSequences(group.get(), res.split.train, [&](const std::vector<int>& d) {
      return executeDemos(executed, d, sim, o.execution, o.seed, progress);
    });
    val_seqs = sharedSequences(group.get(), res.split.val, [&](const std::vector<int>& d) {
      return executeDemos(executed, d, sim, clean, o.seed, nullptr);
    });
    if (!cache.empty() && o.dist.rank == 0) {
      writeSequences(cache + ".train", train_seqs);
      writeSequences(cache + ".val", val_seqs);
    }
  } else if (progress) {
    *progress << "executed demonstrations read from " << cache << ".{train,val}" << std::endl;
  }
  for (const PolicySequence& s : train_seqs) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, s.worst_miss_rad);
  for (const PolicySequence& s : val_seqs) res.expert_worst_miss_rad = std::max(res.expert_worst_miss_rad, s.worst_miss_rad);
  res.execution_seconds = secondsSince(t_exec);
  res.train_samples = tickCount(train_seqs);
  res.val_samples = tickCount(val_seqs);
  res.train_sequences = train_seqs.size();
  res.stats = normStats(train_seqs);
  const double servo_gain = servoStepGain(sim.params);
  res.train_baselines = baselines(train_seqs, servo_gain);
  res.val_baselines = baselines(val_seqs, servo_gain);
  if (progress) {
    char line[200];
    std::snprintf(line, sizeof line, "%zu training rollouts (%zu ticks), %zu validation (%zu ticks) in %.0f s; expert's worst miss %.2g rad",
                  train_seqs.size(), res.train_samples, val_seqs.size(), res.val_samples, res.execution_seconds,
                  res.expert_worst_miss_rad);
    *progress << line << std::endl;
  }

  PolicyNet net(o.arch, o.conditioning);
  net->setNormalisation(res.stats);
  net->setCentroids(data.centroids);
  res.law_gain = lawGain(o, sim);
  net->setLawGain(res.law_gain);
  // A dropped input's weights stay zero, restored after every optimiser step. The runtime
  // multiplies a(t-1) by those weights, so model.bin needs no other mark and nao_rt runs it
  // unchanged.
  const auto holdInputConstraints = [&] {
    if (o.previous_action) return;
    torch::NoGradGuard no_grad;
    net->embed_in->weight[1].zero_();
    net->embed_act->weight.zero_();
  };
  holdInputConstraints();
  SequenceTensors train = toTensors(net, train_seqs);
  SequenceTensors val = toTensors(net, val_seqs);

  std::vector<torch::Tensor> params = net->trainableParameters();
  RunLatent latent{nullptr};
  if (o.latent_dims > 0) {
    latent = RunLatent(o.latent_dims, o.arch.d_model);
    for (const torch::Tensor& t : latent->parameters()) params.push_back(t);
  }
  const double period_s = ControllerParams{}.period_s;
  // The codes a run takes at run time (model.bin's "run_codes"), scored with every epoch; the
  // closed-loop phase picks its rollouts' codes and targets from their starts and DTW tables.
  RunCodeSource codes;
  if (latent || o.closed_loop.enabled()) codes = runCodeSource(data, train_seqs, sim.arm, o.arch.d_model);
  ClosedLoopData cl;
  if (o.closed_loop.enabled())
    cl = closedLoopData(data, codes, sim, period_s, ControllerParams{}.workspace_margin_rad);
  auto optimiser = std::make_unique<torch::optim::Adam>(params, torch::optim::AdamOptions(o.lr));
  // The moving average of the weights (--ema): scored, kept and written in place of the trained
  // weights, which the optimiser goes on training. The input constraints are linear, so the
  // average of constrained weights meets them too.
  std::vector<torch::Tensor> ema;
  std::int64_t ema_steps = 0;
  if (o.ema_decay > 0.0)
    for (const torch::Tensor& p : params) ema.push_back(p.detach().clone());
  const auto swapAverage = [&] {
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < ema.size(); ++i) {
      torch::Tensor trained = params[i].detach().clone();
      params[i].copy_(ema[i]);
      ema[i] = trained;
    }
  };
  std::vector<torch::Tensor> best;
  EpochStats best_stats;
  best_stats.rollout_dtw_m = std::numeric_limits<double>::quiet_NaN();
  best_stats.val_loss = std::numeric_limits<double>::infinity();
  double epoch_seconds_sum = 0.0;
  int first_epoch = 1;
  // Epochs max_epochs + 1 .. last_epoch are closed-loop ones.
  const int last_epoch = o.max_epochs + o.closed_loop.epochs;
  if (!o.resume.empty()) {
    const std::vector<std::string> keys = {key, checkpointKey(o, res.fingerprint, true)};
    Checkpoint ck = readCheckpoint(o.resume, keys, params, *optimiser);
    if (ck.key != key && static_cast<int>(ck.history.size()) > o.max_epochs)
      throw UserError("checkpoint " + o.resume + " is past the teacher-forced epochs of another closed-loop run");
    best = std::move(ck.best);
    if (!ema.empty()) {
      if (ck.ema.size() != ema.size()) throw UserError("checkpoint " + o.resume + " holds no moving average");
      ema = std::move(ck.ema);
      ema_steps = ck.ema_steps;
    }
    res.best_epoch = ck.best_epoch;
    res.history = std::move(ck.history);
    for (const EpochStats& e : res.history) {
      epoch_seconds_sum += e.seconds;
      if (e.epoch == res.best_epoch) best_stats = e;
    }
    first_epoch = static_cast<int>(res.history.size()) + 1;
    res.resumed_after = first_epoch - 1;
    if (first_epoch > o.max_epochs + 1)  // the checkpoint's optimiser is the closed-loop one
      static_cast<torch::optim::AdamOptions&>(optimiser->param_groups()[0].options()).lr(o.closed_loop.lr);
  }
  if (group) {
    // Ranks that disagree would call different collectives: refuse before the first batch.
    group->checkSame(res.train_samples, "training samples");
    group->checkInSync(params);
  }
  const bool live = progress && o.live_progress;
  SelectionReference ref;
  if (o.select_by_rollout) {
    ref = selectionReference(data, res.split.val, sim.arm, period_s, latent ? &codes.codes : nullptr);
    res.val_nn_dtw_m = ref.nn_dtw_m;
  }
  // Patience counts within the closed-loop phase when there is one (the teacher-forced epochs all run).
  const auto stopsAfter = [&](int epoch) {
    if (epoch >= last_epoch) return true;
    if (!o.closed_loop.enabled()) return epoch - res.best_epoch >= o.patience;
    return epoch > o.max_epochs && epoch - std::max(res.best_epoch, o.max_epochs) >= o.patience;
  };
  // One optimiser step on the gradient of the global batch's summed loss / global_ticks (each rank
  // adds its share's), then the constraints and the moving average.
  const auto optimiserStep = [&](double clip) {
    if (group) group->sumGradients(params);
    if (clip > 0.0) torch::nn::utils::clip_grad_norm_(params, clip);
    optimiser->step();
    holdInputConstraints();
    if (!ema.empty()) {
      torch::NoGradGuard no_grad;
      const double d = std::min(o.ema_decay, static_cast<double>(1 + ema_steps) / static_cast<double>(10 + ema_steps));
      for (std::size_t i = 0; i < ema.size(); ++i) ema[i].mul_(d).add_(params[i].detach(), 1.0 - d);
      ++ema_steps;
    }
  };

  const bool done_before = !res.history.empty() && stopsAfter(res.history.back().epoch);
  for (int epoch = first_epoch; epoch <= last_epoch && !done_before; ++epoch) {
    const Clock::time_point t_epoch = Clock::now();
    const bool closed_loop = epoch > o.max_epochs;
    if (closed_loop && epoch == o.max_epochs + 1) {
      // The closed-loop phase starts from the kept teacher-forced weights with a fresh optimiser
      // and a fresh moving average.
      torch::NoGradGuard no_grad;
      for (std::size_t i = 0; i < params.size() && i < best.size(); ++i) params[i].copy_(best[i]);
      optimiser = std::make_unique<torch::optim::Adam>(params, torch::optim::AdamOptions(o.closed_loop.lr));
      for (std::size_t i = 0; i < ema.size(); ++i) ema[i] = params[i].detach().clone();
      ema_steps = 0;
    }
    net->train();
    double loss_sum = 0.0, hand_sse = 0.0;
    std::array<double, 3> kind_sse{}, kind_ticks{};
    std::int64_t seen = 0;
    Clock::time_point t_live = Clock::now();
    const auto liveLine = [&](std::int64_t k, std::int64_t n_run) {
      if (!live || secondsSince(t_live) < 0.5) return;
      t_live = Clock::now();
      const double sec = secondsSince(t_epoch);
      char line[160];
      std::snprintf(line, sizeof line, "\r\033[Kepoch %d/%d  batch %lld/%lld  %.0f ticks/s  epoch ~%s left", epoch,
                    last_epoch, static_cast<long long>(k + 1), static_cast<long long>(n_run),
                    static_cast<double>(seen) / sec,
                    duration(sec / static_cast<double>(k + 1) * static_cast<double>(n_run - k - 1)).c_str());
      *progress << line << std::flush;
    };
    if (closed_loop) {
      // The epoch's rollouts in a seeded order, batch by batch through the arm copy.
      const int k_cl = epoch - o.max_epochs;
      const std::vector<ClosedLoopRun> runs = closedLoopEpochRuns(data, cl, sim, period_s, o.closed_loop, o.seed, k_cl);
      const int horizon = closedLoopHorizon(o.closed_loop, k_cl);
      const std::vector<std::size_t> order =
          shuffledIndices(runs.size(), o.seed * 0x9e3779b97f4a7c15ull + 0x5bd1e995ull * static_cast<std::uint64_t>(epoch));
      const auto n_runs = static_cast<std::int64_t>(runs.size());
      const std::int64_t B = o.closed_loop.batch;
      const std::int64_t n_batches = (n_runs + B - 1) / B;
      const std::int64_t n_run = o.max_batches > 0 ? std::min<std::int64_t>(n_batches, o.max_batches) : n_batches;
      for (std::int64_t k = 0; k < n_run; ++k) {
        const std::int64_t b = k * B, e = std::min<std::int64_t>(b + B, n_runs);
        // The global batch's runs and where their segments start: every rank knows them.
        std::vector<const ClosedLoopRun*> batch;
        for (std::int64_t i = b; i < e; ++i) batch.push_back(&runs[order[static_cast<std::size_t>(i)]]);
        const int t0 = closedLoopSegmentStart(
            batch, horizon, o.seed * 0x9e3779b97f4a7c15ull + static_cast<std::uint64_t>(epoch) * 1000003ull + static_cast<std::uint64_t>(k));
        const auto segment = [&](const ClosedLoopRun* r) { return std::min(horizon, r->ticks - t0); };
        std::int64_t global_ticks = 0;
        for (const ClosedLoopRun* r : batch) global_ticks += segment(r);
        const auto [lo, hi] = group ? shardRange(e - b, o.dist.world_size, o.dist.rank) : std::pair<std::int64_t, std::int64_t>{0, e - b};
        optimiser->zero_grad();
        if (hi > lo) {
          const std::vector<const ClosedLoopRun*> mine(batch.begin() + lo, batch.begin() + hi);
          const ClosedLoopLoss l = closedLoopLoss(*net, latent ? latent.get() : nullptr, train, cl, sim, period_s, mine,
                                                  t0, horizon, o.closed_loop);
          (l.loss / static_cast<double>(global_ticks)).backward();
          loss_sum += l.loss.item<double>();
          hand_sse += l.hand_sse_m2;
          for (std::size_t r = 0; r < mine.size(); ++r) {
            const auto kind = static_cast<std::size_t>(mine[r]->kind);
            kind_sse[kind] += l.run_hand_sse_m2[r];
            kind_ticks[kind] += segment(mine[r]);
          }
        }
        optimiserStep(o.closed_loop.grad_clip);
        seen += global_ticks;
        liveLine(k, n_run);
      }
    } else {
      // Batch order: one stream per (seed, epoch), independent of torch's generator and of the
      // world size (a global batch is the same sequences for every world size).
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
        const auto [lo, hi] = group ? shardRange(e - b, o.dist.world_size, o.dist.rank) : std::pair<std::int64_t, std::int64_t>{0, e - b};
        optimiser->zero_grad();
        if (hi > lo) {
          std::vector<std::size_t> index;
          for (std::int64_t i = b + lo; i < b + hi; ++i) index.push_back(order[static_cast<std::size_t>(i)]);
          // This rank's share of the global batch's mean over real ticks: the all-reduced sum of
          // the gradients is the gradient of that mean.
          Padded p = pad(train, index);
          torch::Tensor kl;
          if (latent) {
            // ε of the global batch from (seed, epoch, batch), this rank's rows: the same draws on a
            // resumed run and for every world size.
            const torch::Tensor eps =
                torch::randn({e - b, o.latent_dims},
                             at::detail::createCPUGenerator(o.seed * 0x9e3779b97f4a7c15ull +
                                                            static_cast<std::uint64_t>(epoch) * 1000003ull +
                                                            static_cast<std::uint64_t>(k)),
                             torch::kFloat32)
                    .slice(0, lo, hi);
            const RunLatentImpl::Draw draw = latent->forward(p, eps);
            p.in.z = draw.z_embedded;
            kl = o.latent_kl * (draw.kl * p.mask.sum(1)).sum();
          }
          LossSums s = lossSums(net, p);
          if (kl.defined()) s.loss = s.loss + kl;
          (s.loss / static_cast<double>(global_ticks)).backward();
          loss_sum += s.loss.item<double>();
        }
        optimiserStep(0.0);
        seen += global_ticks;
        liveLine(k, n_run);
      }
    }
    if (group) {
      torch::Tensor total = torch::tensor({loss_sum, hand_sse, kind_sse[0], kind_sse[1], kind_sse[2], kind_ticks[0],
                                           kind_ticks[1], kind_ticks[2]},
                                          torch::kFloat64);
      group->sum(total, "training loss");
      loss_sum = total[0].item<double>();
      hand_sse = total[1].item<double>();
      for (std::size_t i = 0; i < 3; ++i) {
        kind_sse[i] = total[static_cast<std::int64_t>(2 + i)].item<double>();
        kind_ticks[i] = total[static_cast<std::int64_t>(5 + i)].item<double>();
      }
    }
    net->eval();
    swapAverage();  // score the average; the trained weights come back before the next epoch
    EpochStats st;
    st.epoch = epoch;
    st.samples = static_cast<std::size_t>(seen);
    st.train_loss = loss_sum / static_cast<double>(seen);
    if (closed_loop) {
      st.closed_loop_hand_rms_m = std::sqrt(hand_sse / static_cast<double>(seen));
      for (std::size_t i = 0; i < 3; ++i)
        if (kind_ticks[i] > 0) st.closed_loop_kind_rms_m[i] = std::sqrt(kind_sse[i] / kind_ticks[i]);
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
    const bool first_closed_loop = epoch == o.max_epochs + 1 && o.closed_loop.enabled();
    const bool by_fidelity = epoch > o.max_epochs && latent;
    const bool better = best.empty() || first_closed_loop ||
                        (o.select_by_rollout ? betterEpoch(st, best_stats, by_fidelity) : st.val_loss < best_stats.val_loss);
    if (better) {
      best_stats = st;
      res.best_epoch = epoch;
      best.clear();
      for (const torch::Tensor& p : params) best.push_back(p.detach().clone());
    }
    swapAverage();
    // Every rank applied the same summed gradients: a difference is a bug or a mixed group.
    if (group) group->checkInSync(params);
    st.seconds = secondsSince(t_epoch);
    epoch_seconds_sum += st.seconds;
    res.history.push_back(st);
    const bool stop = stopsAfter(epoch);
    if (!o.checkpoint.empty() && o.dist.rank == 0)
      writeCheckpoint(o.checkpoint, closed_loop ? key : checkpointKey(o, res.fingerprint, true), params, *optimiser, best,
                      res.best_epoch, res.history, ema, ema_steps);
    if (progress) {
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
                      live ? "\r\033[K" : "", epoch, last_epoch, phase.c_str(), st.train_loss,
                      closed_loop ? closedLoopText(st).c_str() : "", st.val_loss,
                      1e3 * st.rollout_dtw_m, st.makes_movement ? " moves" : "");
        text = line + moves;
        std::snprintf(line, sizeof line, ")  best @ %d  %.1f s (rollouts %.1f s)  ", res.best_epoch, st.seconds,
                      score_seconds);
        text += line;
      } else {
        std::snprintf(line, sizeof line, "%sepoch %d/%d  %strain %.4g%s  val %.4g (best %.4g @ %d)  %.1f s  %.0f samples/s  ",
                      live ? "\r\033[K" : "", epoch, last_epoch, phase.c_str(), st.train_loss,
                      closed_loop ? closedLoopText(st).c_str() : "", st.val_loss, best_stats.val_loss, res.best_epoch,
                      st.seconds, static_cast<double>(st.samples) / st.seconds);
        text = line;
      }
      *progress << text
                << (stop ? std::string(epoch == last_epoch ? "epoch cap reached" : "early stop")
                         : "~" + duration(epoch_seconds_sum / (epoch - first_epoch + 1) * (last_epoch - epoch)) + " left")
                << std::endl;
    }
    if (stop) break;
  }

  {
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < params.size() && i < best.size(); ++i) params[i].copy_(best[i]);
  }
  net->eval();
  res.net = net;
  if (latent) {
    updateRunCodes(codes, train, *latent);
    res.run_codes = std::move(codes.codes);
  }
  res.train = evaluateLoss(net, train, group.get());
  res.val = evaluateLoss(net, val, group.get());
  res.seconds = secondsSince(t_start);
  double samples = 0.0, seconds = 0.0;
  for (const EpochStats& e : res.history) {
    samples += static_cast<double>(e.samples);
    seconds += e.seconds;
  }
  res.samples_per_s = seconds > 0.0 ? samples / seconds : 0.0;
  return res;
}

}  // namespace nao::tools
