// What a trained policy says about itself: model.bin's metadata and header, and the model card.
#include "nao/controller.hpp"
#include "nao/model_file.hpp"
#include "policy_train.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <sstream>

namespace nao::tools {
namespace {

using ordered_json = nlohmann::ordered_json;

std::string headText(const TrainOptions& o) {
  std::ostringstream s;
  s << "regression of " << (o.arch.chunk == 1 ? "the next action" : "a chunk of " + std::to_string(o.arch.chunk) + " actions")
    << " (MSE)";
  if (o.arch.chunk > 1) s << "; temporal ensemble of the last " << o.arch.chunk << " chunks, equal weights";
  return s.str();
}

// Where an autonomous run of each movement starts: its held-out demonstrations' starts, in
// split order, with their lengths.
ModelStarts heldOutStarts(const PolicyData& data, const TrainResult& r) {
  ModelStarts starts(data.movement_names.size());
  for (int d : r.split.val) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    starts[static_cast<std::size_t>(demo.movement)].push_back(
        {demo.name, static_cast<std::int64_t>(demo.f.size()), demo.start});
  }
  return starts;
}

}  // namespace

std::string modelMetadata(const PolicyData& data, const TrainOptions& o, const TrainResult& r) {
  ordered_json j;
  j["format"] = "nao-rt policy metadata 2";
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
  c["chunk"] = o.arch.chunk;
  c["bins"] = 0;
  c["head"] = "regression";
  c["layer_norm"] = "pre";
  c["conditioning"] = conditioningName(o.conditioning);
  auto& t = j["training"];
  t["seed"] = o.seed;
  t["max_epochs"] = o.max_epochs;
  t["patience"] = o.patience;
  t["val_fraction"] = o.val_fraction;
  t["batch"] = kTrainBatch;
  t["optimizer"] = "adam";
  t["lr"] = o.lr;
  t["loss"] = "mse of the normalised chunk";
  if (o.arch.chunk > 1) t["ensemble_decay"] = 0.0;  // head.ensemble_decay: equal weights
  if (!o.previous_action) t["previous_action_input"] = false;
  if (o.ema_decay > 0.0) t["ema_decay"] = o.ema_decay;
  if (o.latent_dims > 0) t["run_latent"] = {{"dims", o.latent_dims}, {"kl_weight", o.latent_kl}};
  if (o.closed_loop.enabled()) {
    const ClosedLoopOptions& cl = o.closed_loop;
    t["closed_loop"] = {{"epochs", cl.epochs},
                        {"lr", cl.lr},
                        {"batch", cl.batch},
                        {"horizon", cl.horizon},
                        {"horizon_growth", cl.horizon_growth},
                        {"starts", cl.starts},
                        {"perturb_rad", cl.perturb_rad},
                        {"grad_clip", cl.grad_clip},
                        {"hand_weight", cl.hand_weight},
                        {"limit_weight", cl.limit_weight},
                        {"action_weight", cl.action_weight}};
    if (cl.whole_runs) t["closed_loop"]["whole_runs"] = true;
  }
  t["law_gain"] = r.law_gain;
  t["starts"] = o.conditioning == Conditioning::kAutonomous ? "each demonstration's retargeted first pose"
                                                            : "the first key pose";
  // Only when they change the result: single-process files keep their bytes.
  if (o.dist.world_size > 1) t["world_size"] = o.dist.world_size;
  if (o.max_batches > 0) t["max_batches_per_epoch"] = o.max_batches;
  t["select"] = o.select_by_rollout ? "rollouts" : "validation_loss";
  if (o.select_speed_vs_replay) t["select_speed"] = "replay";
  t["batch_unit"] = "sequences";
  auto& ex = t["execution"];
  ex["arm"] = "simulated ODE arm of nao_rt (sim_arm), servo-lagged";
  ex["expert"] = "command ending the tick at f(t+1)";
  ex["reference_input"] = "f(t+1) - q(t), f: online blend of the snapped key poses, pole " + std::to_string(kFeatureBlendPole);
  ex["noisy_rollouts"] = o.execution.noisy_rollouts;
  ex["noise_std_rad"] = kNoiseStdRad;
  ex["noise_corr"] = o.execution.noise_corr;
  ex["expert_iterations"] = o.execution.expert_iterations;
  ex["expert_tol_rad"] = o.execution.expert_tol_rad;
  // Every rollout's expert aims at the tick's f(t+1) ("tick"); "path_search" stays in the
  // metadata with its value of 10, so the files' bytes are those of earlier models.
  ex["noisy_target"] = "tick";
  ex["path_search"] = 10;
  ex["noisy_starts"] = o.execution.other_starts ? "others" : "own";
  auto& d = j["data"];
  d["fingerprint"] = hex64(r.fingerprint);
  // nao_rt retargets the live human the same way (it reads this back).
  d["retarget"] = data.retarget_json.empty() ? ordered_json() : ordered_json::parse(data.retarget_json);
  d["demos"] = data.demos.size();
  d["train_samples"] = r.train_samples;
  d["val_samples"] = r.val_samples;
  j["split"]["train"] = demoNames(data, r.split.train);
  j["split"]["val"] = demoNames(data, r.split.val);
  auto& res = j["result"];
  res["epochs_run"] = r.history.size();
  res["best_epoch"] = r.best_epoch;
  res["train_loss"] = r.train.loss;
  res["val_loss"] = r.val.loss;
  res["train_mse_rad2"] = r.train.mse_rad2;
  res["val_mse_rad2"] = r.val.mse_rad2;
  if (o.select_by_rollout) {
    for (const EpochStats& e : r.history)
      if (e.epoch == r.best_epoch && !e.rollouts.empty()) {
        ordered_json per = ordered_json::object();
        for (std::size_t m = 0; m < e.rollouts.size(); ++m)
          per[data.movement_names[m]] = {{"dtw_m", e.rollouts[m].dtw_m},
                                         {"speed_ratio", e.rollouts[m].speed_ratio},
                                         {"loops_run", e.rollouts[m].loops_run},
                                         {"loops_demo", e.rollouts[m].loops_demo}};
        res["rollouts"] = per;
        res["makes_movement"] = e.makes_movement;
        res["movements_made"] = e.movements_made;
      }
    res["val_nn_dtw_m"] = r.val_nn_dtw_m;
  }
  auto& b = j["baselines_rad2"];
  for (const auto& [name, bl] : {std::pair<const char*, const Baselines*>{"train", &r.train_baselines},
                                 std::pair<const char*, const Baselines*>{"val", &r.val_baselines}}) {
    b[name]["zero_action"] = bl->zero_action;
    b[name]["repeat_last"] = bl->repeat_last;
    b[name]["gain_law"] = bl->gain_law;
  }
  const std::string with_starts = withModelStarts(j.dump(), data.movement_names, heldOutStarts(data, r));
  if (o.conditioning != Conditioning::kAutonomous) return with_starts;
  // Where an autonomous run may go: the demonstrations' joint range (the controller's envelope).
  const std::string with_workspace = withModelWorkspace(with_starts, data.movement_names, demonstratedWorkspace(data));
  return r.run_codes.empty() ? with_workspace : withModelRunCodes(with_workspace, data.movement_names, r.run_codes);
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

namespace {

// The card's table of epochs: losses, the closed loop's hand error, the rollouts' scores, time.
void cardEpochs(std::ostream& s, const PolicyData& data, const TrainOptions& o, const TrainResult& r) {
  char buf[256];
  s << "## Per epoch\n\n";
  const bool rollouts = o.select_by_rollout;
  s << "| epoch | train loss | val loss | val MSE (rad^2) |"
    << (rollouts ? " rollout DTW mm (movements made of all; per movement: DTW, speed ratio, loops run / demos) |" : "")
    << " s | samples/s |\n|---|---|---|---|" << (rollouts ? "---|" : "") << "---|---|\n";
  for (const EpochStats& e : r.history) {
    std::snprintf(buf, sizeof buf, "| %d%s | %.6f | %.6f | %.4e |", e.epoch, e.epoch == r.best_epoch ? " *" : "",
                  e.train_loss, e.val_loss, e.val_mse_rad2);
    s << buf;
    if (std::isfinite(e.closed_loop_hand_rms_m)) {
      // A closed-loop epoch: its loss is the rollouts', with their hand error against the targets.
      std::snprintf(buf, sizeof buf, " closed loop, hand %.1f mm (own %.1f, perturbed %.1f, between %.1f);",
                    1e3 * e.closed_loop_hand_rms_m, 1e3 * e.closed_loop_kind_rms_m[0], 1e3 * e.closed_loop_kind_rms_m[1],
                    1e3 * e.closed_loop_kind_rms_m[2]);
      s << buf;
    }
    if (rollouts) {
      std::snprintf(buf, sizeof buf, " %.1f (makes %d of %zu)", 1e3 * e.rollout_dtw_m, e.movements_made,
                    data.movement_names.size());  // resumed epochs keep the count, not the rollouts
      s << buf;
      for (std::size_t m = 0; m < e.rollouts.size(); ++m) {
        std::snprintf(buf, sizeof buf, "%s%s %.1f, %.2f, %.1f/%.1f", m == 0 ? "; " : "; ", data.movement_names[m].c_str(),
                      1e3 * e.rollouts[m].dtw_m, e.rollouts[m].speed_ratio, e.rollouts[m].loops_run,
                      e.rollouts[m].loops_demo);
        s << buf;
        if (std::isfinite(e.rollouts[m].code_fidelity_m)) {
          std::snprintf(buf, sizeof buf, ", plays %.1f", 1e3 * e.rollouts[m].code_fidelity_m);
          s << buf;
        }
      }
      s << " |";
    }
    std::snprintf(buf, sizeof buf, " %.1f | %.0f |\n", e.seconds,
                  e.seconds > 0.0 ? static_cast<double>(e.samples) / e.seconds : 0.0);
    s << buf;
  }
}

}  // namespace

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
  s << "| tokens / movements / key poses / max_steps | " << o.arch.tokens << " / " << o.arch.movements << " / "
    << o.arch.clusters << " / " << o.arch.max_steps << " |\n";
  s << "| window | " << o.arch.window << " ticks (" << o.arch.window * 0.1 << " s): tokens (tick, joint), encoder causal in time, age bias |\n";
  s << "| head | " << headText(o) << " |\n";
  s << "| law added at run time | "
    << (r.law_gain != 0.0 ? "law.gain " + std::to_string(r.law_gain) + " x r (r = f(t+1) - q: the first-order servo inversion)"
                          : std::string("none: the executed action is the network's"))
    << " |\n";
  s << "| parameters (manifest floats) | " << parameterCount(o.arch) << " |\n";
  s << "| optimiser | Adam, lr " << o.lr << ", batch " << kTrainBatch << " sequences |\n";
  s << "| training rollouts | per demonstration 1 clean + " << o.execution.noisy_rollouts
    << " with AR(1) command noise (ρ " << o.execution.noise_corr << ", σ in {";
  for (std::size_t i = 0; i < kNoiseStdRad.size(); ++i) s << (i ? ", " : "") << kNoiseStdRad[i];
  s << "} rad) on the servo-lagged ODE arm"
    << (o.conditioning == Conditioning::kAutonomous ? ", each from its demonstration's own start" : "")
    << (o.execution.other_starts ? "; the noisy ones from other training demonstrations' starts" : "")
    << "; labels: the expert's command ending each tick at f(t+1) (worst miss ";
  std::snprintf(buf, sizeof buf, "%.2g rad", r.expert_worst_miss_rad);
  s << buf << "; " << r.train_sequences << " training sequences, executed in ";
  std::snprintf(buf, sizeof buf, "%.0f s", r.execution_seconds);
  s << buf << ") |\n";
  if (o.latent_dims > 0) {
    std::size_t codes = 0;
    for (const ModelRunCodes& c : r.run_codes) codes += c.size();
    s << "| run latent | K " << o.latent_dims << ", KL weight " << o.latent_kl << "; " << codes
      << " run codes (one per training demonstration) in the metadata: a run takes the medoid of the "
      << kRunCodeNearest << " demonstrations whose starts are nearest its own (docs/autonomous.md) |\n";
  }
  if (!o.previous_action) s << "| inputs | a(t-1) not read (its weights held at zero) |\n";
  if (o.ema_decay > 0.0) s << "| weights | moving average, decay " << o.ema_decay << " |\n";
  if (o.closed_loop.enabled()) {
    const ClosedLoopOptions& c = o.closed_loop;
    s << "| closed loop | after the " << o.max_epochs << " teacher-forced epochs, " << c.epochs
      << " epochs rolled out through the arm copy (Adam lr " << c.lr << ", " << c.batch
      << " rollouts per step, gradient norm clipped at " << c.grad_clip << "): " << c.starts
      << " rollouts per training demonstration and epoch, from its own start, from it perturbed by " << c.perturb_rad
      << " rad and from points between it and another demonstration's, each with the run code nao_rt gives it "
      << "there, against the medoid replay from that start; segments of " << c.horizon << " ticks growing by "
      << c.horizon_growth << " per epoch, each batch's from a seeded tick after the target's own history "
      << "(docs/autonomous.md) |\n";
  }
  if (o.closed_loop.enabled() && o.closed_loop.whole_runs)
    s << "| closed-loop segments | whole runs: each run's segment from a seeded tick of its own, up to its end |\n";
  s << "| seed | " << o.seed << " |\n";
  s << "| epochs | " << r.history.size() << " run (cap "
    << o.max_epochs + o.closed_loop.epochs << ", patience "
    << o.patience << "), best " << r.best_epoch << " (exported) |\n";
  if (o.select_by_rollout && o.closed_loop.enabled() && o.latent_dims > 0) {
    s << "| model selection | after every epoch the net (the runtime's streaming inference) is rolled out on the "
         "simulated arm from each validation demonstration's start with the run code nao_rt gives it; the closed "
         "loop starts from the teacher-forced epoch whose runs make the most movements, then the lowest DTW to the "
         "nearest validation demonstration; kept: among the closed-loop epochs whose runs stay within the "
         "demonstrations' joint range + 0.1 rad, the one whose runs play their codes most faithfully (the lowest "
         "mean over movements of the median hand-path DTW from a run to the demonstration its code names) |\n";
  } else if (o.select_by_rollout) {
    s << "| model selection | after every epoch the net (the runtime's streaming inference) is rolled out on the "
         "simulated arm from each validation demonstration's start; kept: among the epochs whose runs make the "
         "most movements (median middle-phase speed 0.7-1.3x the demonstrations', loops within ±1, joints within "
         "the demonstrations' range + 0.1 rad, DTW under twice the demonstrations' own), the one with the lowest mean over movements of the median "
         "hand-path DTW to the nearest validation demonstration. Validation demonstrations' own nearest-neighbour "
         "DTW (median):";
    for (std::size_t m = 0; m < r.val_nn_dtw_m.size(); ++m) {
      std::snprintf(buf, sizeof buf, " %s %.1f mm", data.movement_names[m].c_str(), 1e3 * r.val_nn_dtw_m[m]);
      s << buf << (m + 1 < r.val_nn_dtw_m.size() ? "," : "");
    }
    s << " |\n";
  } else {
    s << "| model selection | the lowest validation loss |\n";
  }
  if (o.select_speed_vs_replay)
    s << "| speed bar | each run's middle-phase speed over its medoid replay's (the demonstration its code names, "
         "tracked from its start), median 0.7-1.3 |\n";
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
  s << "\n";

  s << "## Data\n\n";
  s << "- retargeting (the clustered reference q_r, docs/retargeting.md): "
    << (data.retarget_json.empty() ? std::string("not recorded by the data set") : data.retarget_json) << "\n";
  s << "- fingerprint " << hex64(r.fingerprint) << ", movements";
  for (std::size_t m = 0; m < data.movement_names.size(); ++m) s << (m ? ", " : " ") << m << " = " << data.movement_names[m];
  s << "\n- " << data.demos.size() << " demonstrations: " << r.split.train.size() << " training (" << r.train_samples
    << " samples), " << r.split.val.size() << " validation (" << r.val_samples << " samples, val fraction "
    << o.val_fraction << "); the validation demonstrations' starts are the model's autonomous starts\n";
  s << "- validation demonstrations:";
  for (const std::string& n : demoNames(data, r.split.val)) s << ' ' << n;
  s << "\n\n";

  s << "## One-step MSE of the executed action (rad^2, same split)\n\n";
  s << "| predictor | train | validation |\n|---|---|---|\n";
  std::snprintf(buf, sizeof buf, "| this model (epoch %d) | %.4e | %.4e |\n", r.best_epoch, r.train.mse_rad2, r.val.mse_rad2);
  s << buf;
  std::snprintf(buf, sizeof buf, "| zero action | %.4e | %.4e |\n", r.train_baselines.zero_action, r.val_baselines.zero_action);
  s << buf;
  std::snprintf(buf, sizeof buf, "| repeat last action | %.4e | %.4e |\n", r.train_baselines.repeat_last,
                r.val_baselines.repeat_last);
  s << buf;
  std::snprintf(buf, sizeof buf, "| gain law a = g r (g = %.4f) | %.4e | %.4e |\n", servoStepGain(SimParams{}),
                r.train_baselines.gain_law, r.val_baselines.gain_law);
  s << buf << "\n";
  s << "The gain law reads r = f(t+1) − q, the tick's target, which an autonomous model does not see: there it is a "
       "bound on what the target alone explains, not a competitor.\n\n";

  cardEpochs(s, data, o, r);
  s << "\n## Command\n\n```\n" << command_line << "\n```\n";
  if (r.world_size > 1)
    s << "\nRank 0's command: every rank R of the " << r.world_size
      << " ran the same with `--rank R` (`toolchain/nao train --procs " << r.world_size
      << "` starts them; the bytes depend on the world size, docs/training.md).\n";
  return s.str();
}

}  // namespace nao::tools
