// nao_toolchain train: the body-part Transformer policy on a clustered data set -> model.bin.
#include "nao/arm_model.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_train.hpp"

#include <nlohmann/json.hpp>

#include <malloc.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <exception>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

namespace nao::tools {
namespace {

struct TrainArgs {
  std::string config = "paper", out, data, conditioning = "reference", urdf = NAO_DEFAULT_URDF, card;
  std::string rendezvous, interface, checkpoint, resume, execution_cache;
  std::uint64_t seed = 1;
  int epochs = 200, patience = 10, world_size = 1, rank = 0, max_batches = 0, window = 0;
  double val_fraction = 0.2, lr = 6e-5, timeout = 300;
  std::string select = "val-loss";
  // The training method's options: recipe-only (recipeOnlyOptions).
  int chunk = 0;
  int noisy_rollouts = ExecutionOptions{}.noisy_rollouts;
  std::string noisy_starts = "own";
  bool no_previous_action = false;
  int latent_dims = 0;
  double latent_kl = 1e-2;
  double ema = 0.0;
  ClosedLoopOptions closed_loop;
  bool select_speed_vs_replay = false;
};

// The process's own argv (Linux), shell-quoted where needed; empty if unavailable.
std::string ownCommandLine() {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  std::string raw((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::string out, arg;
  const auto flush = [&] {
    const bool plain = !arg.empty() && arg.find_first_not_of(
                                           "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_./=:,+@%") ==
                                           std::string::npos;
    if (!out.empty()) out += ' ';
    if (plain) {
      out += arg;
    } else {
      out += '\'';
      for (char c : arg) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
      out += '\'';
    }
    arg.clear();
  };
  for (char c : raw) {
    if (c == '\0')
      flush();
    else
      arg += c;
  }
  if (!arg.empty()) flush();
  return out;
}

void run(const TrainArgs& a) {
  const PolicyData data = loadPolicyData(a.data);
  TrainOptions o;
  o.config_name = a.config;
  o.arch = a.config == "paper" ? paperArch() : smallArch();
  if (o.arch.movements != data.movements() || o.arch.clusters != data.clusters())
    std::printf("train: architecture follows the data: %d movements (config %d), %d clusters (config %d)\n",
                data.movements(), o.arch.movements, data.clusters(), o.arch.clusters);
  o.arch.movements = data.movements();
  o.arch.clusters = data.clusters();
  o.conditioning = a.conditioning == "reference" ? Conditioning::kReference : Conditioning::kAutonomous;
  o.seed = a.seed;
  o.max_epochs = a.epochs;
  o.patience = a.patience;
  o.val_fraction = a.val_fraction;
  o.lr = a.lr;
  o.execution.noisy_rollouts = a.noisy_rollouts;
  o.execution.other_starts = a.noisy_starts == "others";
  o.previous_action = !a.no_previous_action;
  o.latent_dims = a.latent_dims;
  o.latent_kl = a.latent_kl;
  o.ema_decay = a.ema;
  o.closed_loop = a.closed_loop;
  if (a.window > 0) o.arch.window = a.window;
  if (a.chunk > 0) o.arch.chunk = a.chunk;
  o.dist.world_size = a.world_size;
  o.dist.rank = a.rank;
  o.dist.rendezvous = a.rendezvous;
  o.dist.interface = a.interface;
  o.dist.timeout_s = a.timeout;
  o.checkpoint = a.checkpoint;
  o.resume = a.resume;
  o.execution_cache = a.execution_cache;
  o.max_batches = a.max_batches;
  o.select_by_rollout = a.select == "rollouts";
  o.select_speed_vs_replay = a.select_speed_vs_replay;
  o.live_progress = isatty(fileno(stdout)) != 0;
  if (a.rank >= a.world_size)
    throw UserError("--rank " + std::to_string(a.rank) + " must be below --world-size " + std::to_string(a.world_size));
  if (a.world_size > 1 && a.rendezvous.empty())
    throw UserError("--world-size " + std::to_string(a.world_size) + " needs --rendezvous tcp://HOST:PORT or file://PATH");
  const bool writer = a.rank == 0;  // rank 0 writes the model, the card and the checkpoints

  // The URDF first: a bad path should fail before minutes of training.
  std::vector<TrainedJoint> joints;
  std::unique_ptr<SimModel> sim;
  try {
    const ArmModel arm = loadArmModel(a.urdf);
    joints = trainedJoints(arm);
    // The arm the demonstrations are executed on: nao_rt's simulated arm, default servos.
    sim = std::make_unique<SimModel>(makeSimModel(arm));
  } catch (const ArmModelError& e) {
    throw UserError(e.what());
  }

  // Each Adam step and backward pass allocates tensors of up to the 24 MB of the paper model's
  // parameters; above glibc's default threshold they are mmap'ed and unmapped every time, and
  // their pages fault in afresh (~1.3 M minor faults in a run of 40 batches). Kept in the heap instead
  // (the threshold's 64-bit maximum, 32 MB, and no trimming), the same arithmetic runs ~4 %
  // faster with the same bytes out (docs/training.md, "Speed").
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, 1024 * 1024 * 1024);

  if (a.world_size > 1)
    std::printf("train: rank %d of %d, rendezvous %s\n", a.rank, a.world_size, a.rendezvous.c_str());
  if (!writer) {
    // The other ranks train and check, quietly; rank 0 reports and writes.
    std::fflush(stdout);
    const TrainResult r = trainPolicy(data, *sim, o, nullptr);
    std::printf("train: rank %d done after %zu epochs (rank 0 writes %s)\n", a.rank, r.history.size(), a.out.c_str());
    return;
  }
  std::printf("train: %s, %s conditioning, seed %llu; data %s: %zu demos, movements", a.config.c_str(),
              a.conditioning.c_str(), static_cast<unsigned long long>(a.seed), hex64(dataFingerprint(data)).c_str(),
              data.demos.size());
  for (std::size_t m = 0; m < data.movement_names.size(); ++m) std::printf(" %zu=%s", m, data.movement_names[m].c_str());
  std::printf(", K %d; %zu parameters\n", data.clusters(), parameterCount(o.arch));
  std::fflush(stdout);

  const TrainResult r = trainPolicy(data, *sim, o, &std::cout);
  const ModelHeader header = modelHeader(data, o, r, joints);
  std::uint64_t checksum = 0;
  try {
    checksum = writeModelFile(a.out, header, manifestFloats(r.net));
  } catch (const ModelFileError& e) {
    throw UserError(e.what());
  }
  std::printf("train: %zu epochs, best %d: val MSE %.4e rad^2 (zero action %.4e, repeat last %.4e, gain law %.4e), "
              "train %.4e rad^2\n",
              r.history.size(), r.best_epoch, r.val.mse_rad2, r.val_baselines.zero_action,
              r.val_baselines.repeat_last, r.val_baselines.gain_law, r.train.mse_rad2);
  std::printf("train: %zu train / %zu val ticks -> %s (checksum %s), %.1f s\n", r.train_samples, r.val_samples,
              a.out.c_str(), hex64(checksum).c_str(), r.seconds);
  if (!a.card.empty()) {
    std::string command = ownCommandLine();
    if (command.empty()) command = "nao_toolchain train --config " + a.config + " --out " + a.out + " --data " + a.data;
    // The BLAS libtorch calls is part of the bytes (toolchain/nao train preloads serial
    // OpenBLAS): the card's command carries the preload it ran with.
    if (const char* preload = std::getenv("LD_PRELOAD"); preload != nullptr && *preload != '\0')
      command = "LD_PRELOAD=" + std::string(preload) + " " + command;
    std::ofstream card(a.card);
    if (!card) throw UserError("cannot write " + a.card);
    card << modelCard(data, o, r, command, a.out);
    if (!card) throw UserError("cannot write " + a.card);
    std::printf("train: model card -> %s\n", a.card.c_str());
  }
}

// A recipe-only option: sets its field from the recipe's value as text, or throws UserError.
using RecipeSetter = std::function<void(const std::string& value)>;

// An integer option of a recipe in [lo, hi].
RecipeSetter recipeInt(int& field, int lo, int hi) {
  return [&field, lo, hi](const std::string& v) {
    std::size_t used = 0;
    int x = 0;
    try {
      x = std::stoi(v, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != v.size() || used == 0 || x < lo || x > hi)
      throw UserError("'" + v + "' is not an integer in " + std::to_string(lo) + ".." + std::to_string(hi));
    field = x;
  };
}

// A recipe value read whole as a number into x; false if it is not one.
bool parseRecipeNumber(const std::string& v, double& x) {
  std::size_t used = 0;
  try {
    x = std::stod(v, &used);
  } catch (const std::exception&) {
    return false;
  }
  return used != 0 && used == v.size();
}

// A positive number option of a recipe.
RecipeSetter recipePositive(double& field) {
  return [&field](const std::string& v) {
    double x = 0.0;
    if (!parseRecipeNumber(v, x) || !(x > 0.0) || !std::isfinite(x)) throw UserError("'" + v + "' is not a positive number");
    field = x;
  };
}

// A number option of a recipe in [lo, hi] (`range`: the bounds as the message names them).
RecipeSetter recipeNumber(double& field, double lo, double hi, const std::string& range) {
  return [&field, lo, hi, range](const std::string& v) {
    double x = 0.0;
    if (!parseRecipeNumber(v, x) || !(x >= lo && x <= hi)) throw UserError("'" + v + "' is not a number in " + range);
    field = x;
  };
}

// An on/off option of a recipe: true or false.
RecipeSetter recipeFlag(bool& field) {
  return [&field](const std::string& v) {
    if (v != "true" && v != "false") throw UserError("'" + v + "' is not true or false");
    field = v == "true";
  };
}

// The training options a recipe file may set that have no command-line flag: the training
// method's (execution, head, latent, averaging, closed loop, selection's speed bar). A
// recipe names them and `train --help` does not grow with them; docs/training.md lists them all,
// docs/autonomous.md says what the on-policy ones do.
std::map<std::string, RecipeSetter> recipeOnlyOptions(TrainArgs& a) {
  std::map<std::string, RecipeSetter> o;
  // Rollouts per training demonstration with AR(1) command noise besides the clean one (DART).
  o["noisy-rollouts"] = recipeInt(a.noisy_rollouts, 0, 16);
  // Where they start: own (the demonstration's start) or others (another's of the same movement).
  o["noisy-starts"] = [&a](const std::string& v) {
    if (v != "own" && v != "others") throw UserError("'" + v + "' is not own or others");
    a.noisy_starts = v;
  };
  // Actions each action token predicts per tick (an action chunk; default: the config's, 1).
  o["chunk"] = recipeInt(a.chunk, 1, 32);
  // The net does not see a(t-1) (its input weights held at zero).
  o["no-previous-action"] = recipeFlag(a.no_previous_action);
  // A per-run latent of K dimensions (autonomous; 0: none) and its KL weight per tick.
  o["run-latent"] = recipeInt(a.latent_dims, 0, 256);
  o["latent-kl"] = recipeNumber(a.latent_kl, 0.0, 1e6, "0..1e6");
  // Decay of the moving average of the weights that is scored and written (0: none).
  o["ema"] = recipeNumber(a.ema, 0.0, 0.99999, "0..0.99999");
  // The closed-loop phase after the teacher-forced epochs (closed_loop.hpp ClosedLoopOptions).
  o["closed-loop-epochs"] = recipeInt(a.closed_loop.epochs, 0, 100000);
  o["closed-loop-lr"] = recipePositive(a.closed_loop.lr);
  o["closed-loop-horizon"] = recipeInt(a.closed_loop.horizon, 1, 100000);
  o["closed-loop-horizon-growth"] = recipeInt(a.closed_loop.horizon_growth, 0, 100000);
  o["closed-loop-starts"] = recipeInt(a.closed_loop.starts, 1, 1000);
  o["closed-loop-action-weight"] = recipeNumber(a.closed_loop.action_weight, 0.0, 1e6, "0..1e6");
  // Whole runs: each closed-loop run's segment from a tick of its own, up to its end.
  o["closed-loop-whole-runs"] = recipeFlag(a.closed_loop.whole_runs);
  // "replay": the rollout selection's speed bar on each run's speed over its medoid replay's.
  o["select-speed"] = [&a](const std::string& v) {
    if (v != "replay" && v != "demonstrations") throw UserError("'" + v + "' is not replay or demonstrations");
    a.select_speed_vs_replay = v == "replay";
  };
  return o;
}

// The options of a recipe file (models/recipes/<name>.json: {"train": {"<option>": value, ...}})
// into `cmd`, each as if given on the command line, except those the command line gives itself
// (it wins). Through CLI11's own results, so every value meets its option's checks. Keys of
// `recipe_only` (no command-line flag) go to their setters.
void applyRecipe(CLI::App& cmd, const std::string& path, const std::map<std::string, RecipeSetter>& recipe_only) {
  std::ifstream in(path);
  if (!in) throw UserError("cannot read the recipe " + path);
  nlohmann::json recipe;
  try {
    recipe = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw UserError(path + ": not JSON (" + e.what() + ")");
  }
  if (!recipe.is_object() || !recipe.contains("train") || !recipe["train"].is_object())
    throw UserError(path + ": a recipe is an object with an object \"train\" of training options");
  const auto text = [&](const std::string& key, const nlohmann::json& v) -> std::string {
    if (v.is_string()) return v.get<std::string>();
    if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
    if (v.is_number_integer()) return std::to_string(v.get<long long>());
    if (v.is_number()) {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
      return buf;
    }
    throw UserError(path + ": option '" + key + "' is not a string, number or boolean");
  };
  for (const auto& [key, value] : recipe["train"].items()) {
    if (key == "recipe" || key == "out" || key == "data" || key == "card")
      throw UserError(path + ": '" + key + "' is given on the command line, not in a recipe");
    if (const auto only = recipe_only.find(key); only != recipe_only.end()) {
      try {
        only->second(text(key, value));
      } catch (const UserError& e) {
        throw UserError(path + ": " + key + ": " + e.what());
      }
      continue;
    }
    CLI::Option* opt = nullptr;
    try {
      opt = cmd.get_option("--" + key);
    } catch (const CLI::OptionNotFound&) {
      throw UserError(path + ": no training option --" + key +
                      " (nao_toolchain train --help; the recipe-only ones: docs/training.md)");
    }
    if (opt->count() > 0) continue;  // the command line's own value
    std::vector<std::string> values;
    if (value.is_array())
      for (const nlohmann::json& v : value) values.push_back(text(key, v));
    else
      values.push_back(text(key, value));
    if (opt->get_expected_max() == 0) {  // a flag: true sets it, false leaves it
      if (values.size() != 1 || (values[0] != "true" && values[0] != "false"))
        throw UserError(path + ": --" + key + " is a flag: true or false");
      if (values[0] == "false") continue;
    }
    try {
      opt->add_result(values);
      opt->run_callback();
    } catch (const CLI::Error& e) {
      throw UserError(path + ": --" + key + ": " + e.what());
    }
  }
}

void setup(CLI::App& app) {
  auto args = std::make_shared<TrainArgs>();
  CLI::App* cmd = app.add_subcommand(
      "train",
      "Trains the body-part Transformer policy (docs/policy.md) on a clustered data set: DATA/centroids.json\n"
      "and DATA/<movement>_<index>/features.csv (nao_toolchain cluster). Split by demonstration, normalisation\n"
      "from the training split, Adam; the epoch exported is the best by the validation loss or, for an\n"
      "autonomous model, by its rollouts from the held-out demonstrations' starts (--select).\n"
      "One thread per process and seeded: two equal runs write byte-identical model.bin files.\n"
      "Data-parallel over libtorch's c10d Gloo process group (docs/training.md): start the same command\n"
      "once per rank with --world-size N --rank R --rendezvous URL (toolchain/nao train --procs N does it\n"
      "on one machine); each rank takes a slice of every global batch of 2 sequences, the gradients\n"
      "are summed by all-reduce, rank 0 writes the model, the card and the checkpoints. Bit-identical for\n"
      "a fixed world size and seed; world size 1 (the default) is the single-process trainer.");
  cmd->add_option("--config", args->config, "Architecture: paper (4+4 layers, d_model 128) or small (tests)")
      ->check(CLI::IsMember({"paper", "small"}))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "model.bin to write")->required();
  cmd->add_option("--data", args->data, "Clustered data set directory")->required()->check(CLI::ExistingDirectory);
  cmd->add_option("--conditioning", args->conditioning,
                  "reference (snapped human key pose r(t)) or autonomous (paper §4.1: movement + step)")
      ->check(CLI::IsMember({"reference", "autonomous"}))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Seed of the weights, the split and the batch order")->capture_default_str();
  cmd->add_option("--epochs", args->epochs, "Maximum epochs (early stopping usually ends sooner)")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--patience", args->patience, "Epochs without a new best validation loss before stopping")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--val-fraction", args->val_fraction, "Validation share of each movement's demonstrations")
      ->check(CLI::Range(0.01, 0.99))
      ->capture_default_str();
  cmd->add_option("--lr", args->lr, "Adam learning rate")->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--window", args->window,
                  "Ticks of history the policy sees (W; default: the config's, 20 for paper, 8 for small). "
                  "Another W needs a nao_rt built for it (toolchain/nao build --model FILE) and, for --select "
                  "rollouts, the toolchain's step compiled for it (toolchain_dims.hpp)")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--urdf", args->urdf, "Robot description (joint names and limits stored in the model)")
      ->check(CLI::ExistingFile)
      ->capture_default_str();
  cmd->add_option("--card", args->card, "Also write a Markdown model card here");
  cmd->add_option("--world-size", args->world_size, "Ranks training together (data-parallel); 1: this process alone")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  cmd->add_option("--rank", args->rank, "This process's rank, 0..world-size-1 (rank 0 writes the outputs)")
      ->check(CLI::Range(0, 4095))
      ->capture_default_str();
  cmd->add_option("--rendezvous", args->rendezvous,
                  "Where the ranks meet: tcp://HOST:PORT (rank 0 listens there; the others connect) or "
                  "file://PATH (a fresh file every rank can reach, e.g. on a shared disk)");
  cmd->add_option("--interface", args->interface,
                  "Network interface for Gloo's connections (e.g. eth0); default: loopback for file:// and "
                  "tcp://127.0.0.1, else the address the host name resolves to");
  cmd->add_option("--timeout", args->timeout,
                  "Seconds a rank waits for the rendezvous or any exchange before it gives up with an error "
                  "(a dead or stuck rank ends every rank)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--checkpoint", args->checkpoint,
                  "Write the training state here after every epoch (rank 0; replaced atomically)");
  cmd->add_option("--resume", args->resume,
                  "Continue from this checkpoint (same data and options; any world size; --epochs and "
                  "--patience may change)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--execution-cache", args->execution_cache,
                  "Keep the executed demonstrations in this directory and read them back in later runs of the "
                  "same data, split, seed and execution options (other heads or training options): the same bytes, "
                  "without executing again");
  cmd->add_option("--max-batches", args->max_batches,
                  "Stop every epoch after this many global batches (timing runs; recorded in the model)")
      ->check(CLI::Range(0, 1 << 30))
      ->capture_default_str();
  cmd->add_option("--select", args->select,
                  "Which epoch is exported (and what patience counts on): val-loss (the validation loss) or "
                  "rollouts (autonomous: after every epoch the net is rolled out on the simulated arm from each "
                  "validation demonstration's start, as nao_rt's autonomous runs; among the epochs whose runs make "
                  "the most movements - middle-phase hand speed 0.7-1.3x the demonstrations', loops within ±1, "
                  "joints within their range + 0.1 rad, DTW under twice their own nearest-neighbour DTW - "
                  "the lowest mean over movements of the median hand-path DTW to the nearest validation "
                  "demonstration wins; paper or small dimensions)")
      ->check(CLI::IsMember({"val-loss", "rollouts"}))
      ->capture_default_str();
  auto recipe = std::make_shared<std::string>();
  cmd->add_option("--recipe", *recipe,
                  "A recipe file (models/recipes/<name>.json): every training option of a committed model, as "
                  "{\"train\": {\"<option>\": value, ...}}; an option also given here on the command line takes "
                  "the command line's value. The training method's options (noisy rollouts, chunk, run latent, "
                  "weight average, closed loop) are set only in a recipe: docs/training.md, "
                  "docs/autonomous.md")
      ->check(CLI::ExistingFile);
  cmd->callback([cmd, args, recipe] {
    if (!recipe->empty()) applyRecipe(*cmd, *recipe, recipeOnlyOptions(*args));
    run(*args);
  });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(train, nao::tools::setup)
