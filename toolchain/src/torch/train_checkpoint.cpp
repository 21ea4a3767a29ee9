#include "train_checkpoint.hpp"

#include "nao/tools/command.hpp"

#include <algorithm>
#include <cstdio>
#include <sstream>

namespace nao::tools {

void writeExecutionKey(std::ostream& k, const ExecutionOptions& e) {
  k << e.noisy_rollouts << " " << e.noise_corr << " " << e.expert_iterations << " " << e.expert_tol_rad;
  for (double q : kNoiseStdRad) k << " " << q;
  if (e.other_starts) k << " other starts";
}

std::string checkpointKey(const TrainOptions& o, std::uint64_t fingerprint, bool teacher_forced_only) {
  std::ostringstream k;
  k.precision(17);
  k << "nao-rt checkpoint 3; data " << hex64(fingerprint) << "; config " << o.config_name << " "
    << parameterCount(o.arch) << "; " << conditioningName(o.conditioning) << "; seed " << o.seed << "; val "
    << o.val_fraction;
  // The head's fields after the chunk (no bins, offset weight 1, ensemble decay 0) and the law's
  // (-1: the servo's) are the text checkpoints have always carried: they stay resumable.
  k << "; batch " << kTrainBatch << "; lr " << o.lr << "; window " << o.arch.window << "; head " << o.arch.chunk
    << " 0 1 0; execution ";
  writeExecutionKey(k, o.execution);
  k << "; batches " << o.max_batches << "; law -1";
  if (!o.previous_action) k << "; no previous action";
  if (o.latent_dims > 0) k << "; latent " << o.latent_dims << " " << o.latent_kl;
  if (o.ema_decay > 0.0) k << "; ema " << o.ema_decay;
  if (o.select_by_rollout) k << "; select rollout";
  if (o.select_speed_vs_replay) k << " speed vs replay";
  const ClosedLoopOptions& c = o.closed_loop;
  if (c.enabled() && !teacher_forced_only)
    k << "; closed loop after " << o.max_epochs << ": lr " << c.lr << " batch " << c.batch
      << " horizon " << c.horizon << " + " << c.horizon_growth << " starts " << c.starts << " perturb " << c.perturb_rad << " clip "
      << c.grad_clip << " hand " << c.hand_weight << " limit " << c.limit_weight << " action " << c.action_weight
      << (c.whole_runs ? " whole runs" : "");
  return k.str();
}

namespace {

// Columns of the history tensor (the per-movement rollout scores are not kept).
constexpr std::int64_t kHistoryColumns = 9;

}  // namespace

void writeCheckpoint(const std::string& path, const std::string& key, const std::vector<torch::Tensor>& params,
                     torch::optim::Adam& optimiser, const std::vector<torch::Tensor>& best, int best_epoch,
                     const std::vector<EpochStats>& history, const std::vector<torch::Tensor>& ema,
                     std::int64_t ema_steps) {
  torch::serialize::OutputArchive archive;
  archive.write("key", c10::IValue(key));
  torch::serialize::OutputArchive p, b, adam;
  for (std::size_t i = 0; i < params.size(); ++i) {
    p.write(std::to_string(i), params[i].detach());
    // No best yet only if every score was NaN: the current weights stand in.
    b.write(std::to_string(i), i < best.size() ? best[i] : params[i].detach());
  }
  archive.write("params", p);
  archive.write("best", b);
  optimiser.save(adam);
  archive.write("adam", adam);
  archive.write("best_epoch", c10::IValue(static_cast<std::int64_t>(best_epoch)));
  torch::Tensor h = torch::empty({static_cast<std::int64_t>(history.size()), kHistoryColumns}, torch::kFloat64);
  for (std::size_t i = 0; i < history.size(); ++i) {
    const EpochStats& e = history[i];
    const double row[kHistoryColumns] = {static_cast<double>(e.epoch), e.train_loss, e.val_loss, e.val_mse_rad2,
                                         e.seconds, static_cast<double>(e.samples), e.rollout_dtw_m,
                                         e.makes_movement ? 1.0 : 0.0, static_cast<double>(e.movements_made)};
    for (std::int64_t c = 0; c < kHistoryColumns; ++c) h[static_cast<std::int64_t>(i)][c] = row[c];
  }
  archive.write("history", h);
  if (!ema.empty()) {
    torch::serialize::OutputArchive a;
    for (std::size_t i = 0; i < ema.size(); ++i) a.write(std::to_string(i), ema[i]);
    archive.write("ema", a);
    archive.write("ema_steps", c10::IValue(ema_steps));
  }
  const std::string tmp = path + ".tmp";
  try {
    archive.save_to(tmp);
  } catch (const std::exception& e) {
    throw UserError("cannot write the checkpoint " + tmp + ": " + e.what());
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw UserError("cannot rename " + tmp + " to " + path);
}

Checkpoint readCheckpoint(const std::string& path, const std::vector<std::string>& keys,
                          std::vector<torch::Tensor>& params, torch::optim::Adam& optimiser) {
  Checkpoint ck;
  try {
    torch::serialize::InputArchive archive;
    archive.load_from(path);
    c10::IValue v;
    archive.read("key", v);
    if (std::find(keys.begin(), keys.end(), v.toStringRef()) == keys.end())
      throw UserError("checkpoint " + path + " belongs to another run: it has '" + v.toStringRef() + "', this run '" +
                      keys.front() + "'");
    ck.key = v.toStringRef();
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
      e.rollout_dtw_m = h[i][6].item<double>();
      e.makes_movement = h[i][7].item<double>() != 0.0;
      e.movements_made = static_cast<int>(h[i][8].item<double>());
      ck.history.push_back(e);
    }
    // The key names the moving average when the run has one, so only such runs find it here.
    torch::serialize::InputArchive a;
    if (archive.try_read("ema", a)) {
      for (std::size_t i = 0; i < params.size(); ++i) {
        torch::Tensor t;
        a.read(std::to_string(i), t);
        ck.ema.push_back(t);
      }
      archive.read("ema_steps", v);
      ck.ema_steps = v.toInt();
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

}  // namespace nao::tools
