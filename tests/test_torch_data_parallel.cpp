// Data-parallel training over c10d's Gloo process group (docs/training.md): every rank is a
// child process of this test (fork), the ranks meet over a FileStore in a fresh temp
// directory. The shards cover every global batch once; the summed shard gradients are the
// single-process gradient of the global batch; world size 2 is bit-reproducible and agrees
// with world size 1; a killed rank or a missing one ends the others with an error within the
// timeout; a checkpoint resumes to the same bytes, and under another world size; the executed
// and the scored rollouts are shared so that every rank holds what one process makes.
#include "data_parallel.hpp"
#include "nao/controller.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "train_data.hpp"
#include "train_select.hpp"
#include "support/small_policy_data.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

using namespace nao;
using namespace nao::tools;
using nao::test::smallData;

namespace {

using Clock = std::chrono::steady_clock;

using nao::test::smallOptions;
using nao::test::smallSim;

// A fresh directory per use, removed afterwards: a FileStore must never see a previous run's file.
struct TempDir {
  std::string path = (std::filesystem::temp_directory_path() / "nao_dp_XXXXXX").string();
  TempDir() { REQUIRE(mkdtemp(path.data()) != nullptr); }
  ~TempDir() { std::filesystem::remove_all(path); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
};

std::vector<std::uint8_t> modelBytes(const TrainOptions& o, const TrainResult& r) {
  return encodeModel(modelHeader(smallData(), o, r, trainedJoints(loadArmModel(nao::test::kUrdfPath))),
                     manifestFloats(r.net));
}

std::vector<std::uint8_t> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct RankExit {
  bool exited = false;  ///< false: killed by a signal
  int code = -1;
  double seconds = 0.0;  ///< from launch to exit
  Clock::time_point ended;
  std::string error;     ///< what the rank threw (dir/rank<R>.err)
};

// Forks one child per rank; child r runs body(r) and exits 0, or writes the exception's
// message to dir/rank<r>.err and exits 1. on_started (if set) runs in the parent once all
// children exist, with their pids. Waits for every child.
std::vector<RankExit> runRanks(int world, const std::string& dir, const std::function<void(int)>& body,
                               const std::function<void(const std::vector<pid_t>&)>& on_started = nullptr) {
  (void)smallData();  // built once, before the fork
  const Clock::time_point t0 = Clock::now();
  std::vector<pid_t> pids;
  for (int r = 0; r < world; ++r) {
    const pid_t pid = fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
      int code = 0;
      try {
        body(r);
      } catch (const std::exception& e) {
        std::ofstream(dir + "/rank" + std::to_string(r) + ".err") << e.what();
        code = 1;
      }
      std::_Exit(code);  // no doctest or static destructors in the child
    }
    pids.push_back(pid);
  }
  if (on_started) on_started(pids);
  std::vector<RankExit> out(static_cast<std::size_t>(world));
  for (int r = 0; r < world; ++r) {
    int status = 0;
    REQUIRE(waitpid(pids[static_cast<std::size_t>(r)], &status, 0) == pids[static_cast<std::size_t>(r)]);
    RankExit& x = out[static_cast<std::size_t>(r)];
    x.ended = Clock::now();
    x.seconds = std::chrono::duration<double>(x.ended - t0).count();
    x.exited = WIFEXITED(status);
    x.code = x.exited ? WEXITSTATUS(status) : -1;
    x.error = nao::test::readFile(dir + "/rank" + std::to_string(r) + ".err");
  }
  return out;
}

DistOptions dist(int world, int rank, const std::string& dir, double timeout_s = 30) {
  DistOptions d;
  d.world_size = world;
  d.rank = rank;
  d.rendezvous = "file://" + dir + "/store";
  d.timeout_s = timeout_s;
  return d;
}

// Trains with world size `world` in child processes; rank r's model.bin bytes land in
// dir/rank<r>.bin and rank 0's progress in dir/progress.txt. Returns the bytes of every rank.
std::vector<std::vector<std::uint8_t>> trainRanks(const TrainOptions& base, int world, const std::string& dir) {
  const std::vector<RankExit> exits = runRanks(world, dir, [&](int r) {
    TrainOptions o = base;
    o.dist = dist(world, r, dir);
    std::ofstream progress(dir + "/progress.txt");
    const TrainResult res = trainPolicy(smallData(), smallSim(), o, &progress);
    const std::vector<std::uint8_t> bytes = modelBytes(o, res);
    std::ofstream(dir + "/rank" + std::to_string(r) + ".bin", std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  });
  std::vector<std::vector<std::uint8_t>> out;
  for (int r = 0; r < world; ++r) {
    const RankExit& x = exits[static_cast<std::size_t>(r)];
    REQUIRE_MESSAGE((x.exited && x.code == 0), "rank " << r << " failed: " << x.error);
    out.push_back(readBytes(dir + "/rank" + std::to_string(r) + ".bin"));
  }
  return out;
}

}  // namespace

TEST_CASE("shardRange splits every global batch into disjoint contiguous shards that cover it") {
  for (int world = 1; world <= 7; ++world)
    for (std::int64_t n = 0; n <= 40; ++n) {
      std::vector<int> owner(static_cast<std::size_t>(n), -1);
      std::int64_t expected_begin = 0;
      for (int r = 0; r < world; ++r) {
        const auto [begin, end] = shardRange(n, world, r);
        CHECK_MESSAGE(begin == expected_begin, "world " << world << " n " << n << " rank " << r);
        CHECK(end >= begin);
        CHECK(end - begin >= n / world);
        CHECK(end - begin <= n / world + 1);
        for (std::int64_t i = begin; i < end; ++i) {
          CHECK_MESSAGE(owner[static_cast<std::size_t>(i)] == -1, "position " << i << " taken twice");
          owner[static_cast<std::size_t>(i)] = r;
        }
        expected_begin = end;
      }
      CHECK(expected_begin == n);
      for (int o : owner) CHECK(o >= 0);
    }
}

TEST_CASE("the Gloo-summed shard gradients equal the single-process gradient of the global batch") {
  torch::set_num_threads(1);
  const PolicyArch arch = smallArch();
  const std::int64_t n = 8, ticks = 12;  // sequences of 12 ticks (longer than the window)
  // The global batch: seeded normalised sequences and targets, the same in every process.
  const auto batch = [&] {
    torch::manual_seed(7);
    PolicyBatch in{torch::randn({n, ticks, arch.tokens}), torch::randn({n, ticks, arch.tokens}),
                   torch::randn({n, ticks, arch.tokens}), torch::randint(0, arch.movements, {n}, torch::kInt64)};
    return std::make_pair(in, torch::randn({n, ticks, arch.tokens, arch.chunk}));
  };
  const auto freshNet = [&] {
    torch::manual_seed(3);
    return PolicyNet(arch, Conditioning::kAutonomous);
  };

  // Single process: the mean loss of the whole batch, as the trainer's world-size-1 loop.
  const PolicyNet single = freshNet();
  const auto [in, target] = batch();
  torch::mse_loss(single->forward(in).chunk, target).backward();
  const std::vector<torch::Tensor> params = single->trainableParameters();

  const TempDir tmp;
  const std::string& dir = tmp.path;
  const int world = 3;  // uneven shards: 3 + 3 + 2
  const std::vector<RankExit> exits = runRanks(world, dir, [&](int r) {
    torch::set_num_threads(1);
    ProcessGroup group(dist(world, r, dir));
    const PolicyNet net = freshNet();
    const auto [b_in, b_target] = batch();
    const auto [lo, hi] = shardRange(n, world, r);
    const torch::Tensor idx = torch::arange(lo, hi, torch::kInt64);
    const PolicyBatch shard{b_in.qn.index_select(0, idx), b_in.an.index_select(0, idx), b_in.rn.index_select(0, idx),
                            b_in.movement.index_select(0, idx)};
    ((net->forward(shard).chunk - b_target.index_select(0, idx)).square().sum() /
     static_cast<double>(n * ticks * arch.tokens))
        .backward();
    const std::vector<torch::Tensor> p = net->trainableParameters();
    group.sumGradients(p);
    torch::serialize::OutputArchive archive;
    for (std::size_t i = 0; i < p.size(); ++i) archive.write(std::to_string(i), p[i].grad());
    archive.save_to(dir + "/grad" + std::to_string(r) + ".pt");
  });
  for (int r = 0; r < world; ++r)
    REQUIRE_MESSAGE((exits[static_cast<std::size_t>(r)].exited && exits[static_cast<std::size_t>(r)].code == 0),
                    "rank " << r << ": " << exits[static_cast<std::size_t>(r)].error);

  std::vector<std::vector<torch::Tensor>> grads(world);
  for (int r = 0; r < world; ++r) {
    torch::serialize::InputArchive archive;
    archive.load_from(dir + "/grad" + std::to_string(r) + ".pt");
    for (std::size_t i = 0; i < params.size(); ++i) {
      torch::Tensor g;
      archive.read(std::to_string(i), g);
      grads[static_cast<std::size_t>(r)].push_back(g);
    }
  }
  // Float32 sums in another order: equal to rounding. Relative to each tensor's scale, except
  // the attention key biases (*.bk), whose gradient is 0 in exact arithmetic (softmax ignores
  // a shift of all keys) and rounding noise here: they are held to the model's largest gradient.
  std::vector<std::string> names;
  for (const auto& [name, t] : manifestTensors(single))
    if (t.requires_grad()) names.push_back(name);
  REQUIRE(names.size() == params.size());
  double largest = 0.0;
  for (const torch::Tensor& p : params) largest = std::max(largest, p.grad().abs().max().item<double>());
  double worst = 0.0;
  for (std::size_t i = 0; i < params.size(); ++i) {
    const torch::Tensor& g1 = params[i].grad();
    // Every rank holds the same bytes after the all-reduce.
    for (int r = 1; r < world; ++r) CHECK(torch::equal(grads[0][i], grads[static_cast<std::size_t>(r)][i]));
    const bool key_bias = names[i].size() > 3 && names[i].compare(names[i].size() - 3, 3, ".bk") == 0;
    const double scale = key_bias ? largest : g1.abs().max().item<double>();
    const double diff = (grads[0][i] - g1).abs().max().item<double>();
    if (!key_bias && scale > 0.0) worst = std::max(worst, diff / scale);
    CHECK_MESSAGE(diff <= 1e-5 * scale, names[i] << ": |Δgrad| " << diff << " of scale " << scale);
  }
  MESSAGE("worst relative gradient difference, world size 3 vs 1 (key biases aside): " << worst);
  // Sanity of the comparison itself: the gradients are not all zero.
  CHECK(params.front().grad().abs().max().item<double>() > 0.0);
}

namespace {

// The largest difference of two model.bin files' weights, attention key biases aside, and where.
std::pair<double, std::string> largestWeightDifference(const std::vector<std::uint8_t>& a,
                                                       const std::vector<std::uint8_t>& b) {
  const ModelFile f1 = decodeModel(a, "first"), f2 = decodeModel(b, "second");
  REQUIRE(f1.tensors.size() == f2.tensors.size());
  double worst = 0.0;
  std::string worst_name;
  for (std::size_t i = 0; i < f1.tensors.size(); ++i) {
    const std::string& name = f1.tensors[i].spec.name;
    if (name.size() > 3 && name.compare(name.size() - 3, 3, ".bk") == 0) continue;
    for (std::size_t k = 0; k < f1.tensors[i].spec.count(); ++k) {
      const double d = std::abs(static_cast<double>(f1.data(i)[k]) - f2.data(i)[k]);
      if (d > worst) {
        worst = d;
        worst_name = name;
      }
    }
  }
  return {worst, worst_name};
}

}  // namespace

TEST_CASE("world size 2 twice gives byte-identical model.bin bytes on every rank, and agrees with world size 1") {
  torch::set_num_threads(1);
  const TrainOptions o = smallOptions(11, 1);
  const std::vector<std::vector<std::uint8_t>> a = trainRanks(o, 2, TempDir().path);
  const std::vector<std::vector<std::uint8_t>> b = trainRanks(o, 2, TempDir().path);
  CHECK_MESSAGE(a[0] == b[0], "two world-size-2 runs with seed 11 gave different bytes");
  CHECK_MESSAGE(a[0] == a[1], "ranks 0 and 1 ended with different models");

  const TrainResult single = trainPolicy(smallData(), smallSim(), o, nullptr);
  const std::vector<std::uint8_t> one = modelBytes(o, single);
  CHECK(one != a[0]);  // the metadata records the world size, and the sums differ in rounding
  const nlohmann::json meta = nlohmann::json::parse(decodeModel(a[0], "world 2").header.metadata_json);
  CHECK(meta["training"]["world_size"] == 2);
  CHECK_FALSE(nlohmann::json::parse(decodeModel(one, "world 1").header.metadata_json)["training"].contains("world_size"));

  // One epoch (15 Adam steps at lr 1e-3). Float rounding of the other reduction order leaves
  // the weights equal to ~1e-6. The exception is the attention key biases (*.bk): softmax is
  // invariant to a shift of all keys, so their gradient is 0 in exact arithmetic and pure
  // rounding noise in float, which Adam turns into steps of ~lr in any direction; they do not
  // change any output (docs/training.md).
  const auto [worst, worst_name] = largestWeightDifference(one, a[0]);
  MESSAGE("max |w(world 2) - w(world 1)| after one epoch, key biases aside: " << worst << " (" << worst_name << ")");
  CHECK(worst <= 1e-5);
  const double val1 = single.val.mse_rad2, val2 = meta["result"]["val_mse_rad2"].get<double>();
  MESSAGE("validation MSE world 1 " << val1 << ", world 2 " << val2);
  CHECK(std::abs(val2 - val1) <= 0.02 * val1);
}

TEST_CASE("a run latent draws the same noise for every world size: world size 2 agrees with world size 1") {
  torch::set_num_threads(1);
  TrainOptions o = smallOptions(13, 1);
  o.conditioning = Conditioning::kAutonomous;
  o.latent_dims = 4;
  const std::vector<std::vector<std::uint8_t>> two = trainRanks(o, 2, TempDir().path);
  const std::vector<std::uint8_t> one = modelBytes(o, trainPolicy(smallData(), smallSim(), o, nullptr));
  const auto [worst, worst_name] = largestWeightDifference(one, two[0]);
  MESSAGE("with a run latent, max |w(world 2) - w(world 1)| after one epoch: " << worst << " (" << worst_name << ")");
  CHECK(worst <= 1e-5);
}

namespace {

// Every field of every sequence, in order, as text with all digits (equal text = equal doubles).
std::string sequencesText(const std::vector<PolicySequence>& seqs) {
  std::ostringstream s;
  s.precision(17);
  for (const PolicySequence& q : seqs) {
    s << q.demo << ' ' << q.movement << ' ' << q.rollout << ' ' << q.worst_miss_rad << '\n';
    for (const std::vector<JointVector>* v : {&q.q, &q.a_prev, &q.r, &q.a}) {
      s << v->size() << ':';
      for (const JointVector& x : *v) s << ' ' << x.transpose();
      s << '\n';
    }
  }
  return s.str();
}

}  // namespace

TEST_CASE("gatherSequences: each rank executes a share of the demonstrations, every rank gets all, in order, to the last bit") {
  torch::set_num_threads(1);
  const PolicyData& data = smallData();
  ExecutionOptions exec;
  exec.noisy_rollouts = 1;
  std::vector<int> demos;
  for (int d = 0; d < static_cast<int>(data.demos.size()); ++d) demos.push_back(d);
  const std::string one = sequencesText(executeDemos(data, demos, smallSim(), exec, 3));
  for (int world : {2, 3}) {
    const TempDir tmp;
    const std::vector<RankExit> exits = runRanks(world, tmp.path, [&](int r) {
      ProcessGroup g(dist(world, r, tmp.path));
      const auto [b, e] = shardRange(static_cast<std::int64_t>(demos.size()), world, r);
      const std::vector<int> mine(demos.begin() + b, demos.begin() + e);
      std::ofstream(tmp.path + "/rank" + std::to_string(r) + ".txt")
          << sequencesText(gatherSequences(g, executeDemos(data, mine, smallSim(), exec, 3)));
    });
    for (int r = 0; r < world; ++r) {
      const RankExit& x = exits[static_cast<std::size_t>(r)];
      REQUIRE_MESSAGE((x.exited && x.code == 0), "rank " << r << " of " << world << " failed: " << x.error);
      CHECK_MESSAGE(nao::test::readFile(tmp.path + "/rank" + std::to_string(r) + ".txt") == one,
                    "rank " << r << " of " << world << " holds other sequences than one process makes");
    }
  }
  // The comparison can fail: another seed gives other noisy rollouts.
  CHECK(sequencesText(executeDemos(data, demos, smallSim(), exec, 4)) != one);
}

TEST_CASE("world size 2 shares the expert's rollouts and the rollout scores: each rank makes its share, every rank gets what one process makes") {
  torch::set_num_threads(1);
  TrainOptions o = smallOptions(47, 1);
  o.conditioning = Conditioning::kAutonomous;
  o.select_by_rollout = true;
  o.execution.noisy_rollouts = 1;  // two sequences per demonstration: the shares are whole demonstrations
  const std::vector<std::vector<std::uint8_t>> a = trainRanks(o, 2, TempDir().path);
  REQUIRE(a[0] == a[1]);
  const TrainResult single = trainPolicy(smallData(), smallSim(), o, nullptr);
  const ModelFile f1 = decodeModel(modelBytes(o, single), "world 1"), f2 = decodeModel(a[0], "world 2");
  // The normalisation is the statistics of all executed training sequences in order: equal
  // bits only if rank 0 got rank 1's sequences exactly, and in place.
  int norms = 0;
  REQUIRE(f1.tensors.size() == f2.tensors.size());
  for (std::size_t i = 0; i < f1.tensors.size(); ++i) {
    const std::string& name = f1.tensors[i].spec.name;
    if (name.rfind("norm.", 0) != 0) continue;
    ++norms;
    CHECK_MESSAGE(std::equal(f1.data(i), f1.data(i) + f1.tensors[i].spec.count(), f2.data(i)), name << " differs");
  }
  CHECK(norms == 6);
  const nlohmann::json m1 = nlohmann::json::parse(f1.header.metadata_json);
  const nlohmann::json m2 = nlohmann::json::parse(f2.header.metadata_json);
  CHECK(m2["data"]["train_samples"] == m1["data"]["train_samples"]);
  CHECK(m2["data"]["val_samples"] == m1["data"]["val_samples"]);
  CHECK(m2["baselines_rad2"] == m1["baselines_rad2"]);
  CHECK(m2["result"]["val_nn_dtw_m"] == m1["result"]["val_nn_dtw_m"]);
  CHECK(m2["starts"] == m1["starts"]);
  // The world-size-2 model's rollouts (each rank rolled out its share of the validation
  // demonstrations, all scored all of them) are what one process scores for the same weights,
  // to the last bit: the kept epoch's weights are the file's.
  PolicyNet net(f2.header.arch, f2.header.conditioning);
  {
    torch::NoGradGuard no_grad;
    const auto tensors = manifestTensors(net);
    REQUIRE(tensors.size() == f2.tensors.size());
    for (std::size_t i = 0; i < tensors.size(); ++i)
      tensors[i].second.view({-1}).copy_(
          torch::from_blob(const_cast<float*>(f2.data(i)), {static_cast<long>(f2.tensors[i].spec.count())}, torch::kFloat));
  }
  net->eval();
  const double period = ControllerParams{}.period_s;
  const SelectionReference ref = selectionReference(smallData(), single.split.val, smallSim().arm, period);
  EpochStats st;
  scoreRuns(netRuns(fromOwnStarts(smallData()), single.split.val, smallSim(), net), ref, smallSim().arm, period, st);
  REQUIRE(st.rollouts.size() == 3);
  for (std::size_t m = 0; m < 3; ++m) {
    const nlohmann::json& got = m2["result"]["rollouts"][smallData().movement_names[m]];
    CAPTURE(smallData().movement_names[m]);
    CHECK(got["dtw_m"].get<double>() == st.rollouts[m].dtw_m);
    CHECK(got["speed_ratio"].get<double>() == st.rollouts[m].speed_ratio);
    CHECK(got["loops_run"].get<double>() == st.rollouts[m].loops_run);
  }
  CHECK(m2["result"]["makes_movement"] == st.makes_movement);
  // The card says how the other ranks ran (the command it shows is rank 0's).
  TrainResult as_two = single;
  as_two.world_size = 2;
  CHECK(modelCard(smallData(), o, as_two, "cmd", "m.bin").find("`toolchain/nao train --procs 2`") != std::string::npos);
  CHECK(modelCard(smallData(), o, single, "cmd", "m.bin").find("--procs") == std::string::npos);
}

namespace {

// Trains world size 2 until rank 1 gets `sig` (after rank 0 reported its first epoch); returns
// rank 0's exit and the seconds from the signal to rank 0's exit.
std::pair<RankExit, double> signalRank1(int sig, double timeout_s) {
  torch::set_num_threads(1);
  const TempDir tmp;
  const std::string& dir = tmp.path;
  const TrainOptions base = smallOptions(5, 100000);  // far longer than the test: only the signal ends it
  Clock::time_point signalled_at;
  const std::vector<RankExit> exits = runRanks(
      2, dir,
      [&](int r) {
        TrainOptions o = base;
        o.dist = dist(2, r, dir, timeout_s);
        std::ofstream progress(dir + "/progress.txt");
        trainPolicy(smallData(), smallSim(), o, r == 0 ? &progress : nullptr);
      },
      [&](const std::vector<pid_t>& pids) {
        const Clock::time_point t0 = Clock::now();
        while (nao::test::readFile(dir + "/progress.txt").find("epoch 1/") == std::string::npos &&
               Clock::now() - t0 < std::chrono::seconds(30))
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        signalled_at = Clock::now();
        kill(pids[1], sig);
        if (sig == SIGSTOP) {
          // Rank 1 hangs; once rank 0 has given up (its error file exists), end rank 1.
          std::thread([p = pids[1], dir, timeout_s] {
            const Clock::time_point t1 = Clock::now();
            while (!std::filesystem::exists(dir + "/rank0.err") &&
                   Clock::now() - t1 < std::chrono::duration<double>(timeout_s + 10.0))
              std::this_thread::sleep_for(std::chrono::milliseconds(20));
            kill(p, SIGKILL);
          }).detach();
        }
      });
  const double after = std::chrono::duration<double>(exits[0].ended - signalled_at).count();
  REQUIRE_MESSAGE(nao::test::readFile(dir + "/progress.txt").find("epoch 1/") != std::string::npos,
                  "rank 0 never finished an epoch");
  return {exits[0], after};
}

}  // namespace

TEST_CASE("a killed rank ends the other rank with an error at once") {
  const double timeout_s = 10.0;
  const auto [rank0, after] = signalRank1(SIGKILL, timeout_s);
  CHECK(rank0.exited);
  CHECK(rank0.code == 1);
  CHECK_MESSAGE(after < timeout_s, "rank 0 took " << after << " s after the kill");
  CHECK_MESSAGE(rank0.error.find("another rank died, stopped or timed out") != std::string::npos,
                "rank 0 said: " << rank0.error);
  MESSAGE("rank 0 after the kill (" << after << " s): " << rank0.error);
}

TEST_CASE("a stopped rank ends the other rank with an error after the timeout") {
  const double timeout_s = 3.0;
  const auto [rank0, after] = signalRank1(SIGSTOP, timeout_s);
  CHECK(rank0.exited);
  CHECK(rank0.code == 1);
  CHECK_MESSAGE(after >= timeout_s - 0.5, "rank 0 gave up " << after << " s after the stop");
  CHECK_MESSAGE(after < timeout_s + 5.0, "rank 0 took " << after << " s after the stop");
  CHECK_MESSAGE(rank0.error.find("another rank died, stopped or timed out") != std::string::npos,
                "rank 0 said: " << rank0.error);
  MESSAGE("rank 0 after the stop (" << after << " s): " << rank0.error);
}

TEST_CASE("ranks started with different options refuse to train, every one with the reason") {
  torch::set_num_threads(1);
  const TempDir tmp;
  const std::string& dir = tmp.path;
  const std::vector<RankExit> exits = runRanks(2, dir, [&](int r) {
    TrainOptions o = smallOptions(5, 1);
    if (r == 1) o.lr = 2e-3;
    o.dist = dist(2, r, dir);
    trainPolicy(smallData(), smallSim(), o, nullptr);
  });
  for (int r = 0; r < 2; ++r) {
    const RankExit& x = exits[static_cast<std::size_t>(r)];
    CHECK(x.exited);
    CHECK(x.code == 1);
    CHECK_MESSAGE(x.error.find("the ranks' options and data differ") != std::string::npos, "rank " << r << ": " << x.error);
  }
}

TEST_CASE("a rank whose peers never come fails the rendezvous with an error after the timeout") {
  torch::set_num_threads(1);
  const TempDir tmp;
  const std::string& dir = tmp.path;
  const double timeout_s = 2.0;
  const std::vector<RankExit> exits = runRanks(1, dir, [&](int) {
    TrainOptions o = smallOptions(5, 1);
    o.dist = dist(2, 0, dir, timeout_s);  // rank 0 of 2; rank 1 never starts
    trainPolicy(smallData(), smallSim(), o, nullptr);
  });
  CHECK(exits[0].exited);
  CHECK(exits[0].code == 1);
  CHECK(exits[0].seconds >= timeout_s);
  CHECK(exits[0].seconds < timeout_s + 10.0);
  CHECK_MESSAGE(exits[0].error.find("rendezvous failed (rank 0 of 2") != std::string::npos,
                "rank 0 said: " << exits[0].error);
  MESSAGE("rank 0 alone (" << exits[0].seconds << " s): " << exits[0].error);
}

TEST_CASE("a checkpoint resumes to the uninterrupted run's bytes, and under another world size") {
  torch::set_num_threads(1);
  const TempDir tmp;
  const std::string& dir = tmp.path;
  const TrainOptions full = smallOptions(13, 3);
  const std::vector<std::uint8_t> uninterrupted = modelBytes(full, trainPolicy(smallData(), smallSim(), full, nullptr));

  TrainOptions first = smallOptions(13, 2);
  first.checkpoint = dir + "/ck.pt";
  trainPolicy(smallData(), smallSim(), first, nullptr);
  REQUIRE(std::filesystem::exists(first.checkpoint));

  TrainOptions rest = smallOptions(13, 3);
  rest.resume = first.checkpoint;
  const TrainResult resumed = trainPolicy(smallData(), smallSim(), rest, nullptr);
  CHECK(resumed.resumed_after == 2);
  REQUIRE(resumed.history.size() == 3);
  CHECK_MESSAGE(modelBytes(rest, resumed) == uninterrupted, "resumed after epoch 2 of 3, the bytes differ");

  // The same checkpoint, continued by two ranks.
  const std::vector<std::vector<std::uint8_t>> two = trainRanks(rest, 2, dir);
  const nlohmann::json meta = nlohmann::json::parse(decodeModel(two[0], "resumed by 2 ranks").header.metadata_json);
  CHECK(meta["result"]["epochs_run"] == 3);
  CHECK(meta["training"]["world_size"] == 2);
  CHECK(std::abs(meta["result"]["val_mse_rad2"].get<double>() - resumed.val.mse_rad2) <= 0.02 * resumed.val.mse_rad2);

  // Another run's checkpoint is refused with the reason.
  TrainOptions other = smallOptions(14, 3);
  other.resume = first.checkpoint;
  CHECK_THROWS_WITH_AS(trainPolicy(smallData(), smallSim(), other, nullptr), doctest::Contains("belongs to another run"), UserError);
}
