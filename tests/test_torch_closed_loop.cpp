// The trainer's closed-loop pieces against the runtime they stand in for: the torch streaming step
// (policy_stream.hpp) against the runtime's stepPolicy and against the module's own sequence
// forward; the differentiable arm tick (arm_copy_torch.hpp) against the copy it wraps and its
// gradient against central differences; a whole unroll (stream + limiter + arm copy) against
// nao_rt's controller driving the ODE arm; and the closed-loop loss's gradient reaching the net.
// Also the trainer's on-policy options: each start's code as the runtime picks it, whole-run
// segments, and selection's speed against the replay.
#include "arm_copy_torch.hpp"
#include "closed_loop.hpp"
#include "nao/controller.hpp"
#include "nao/policy.hpp"
#include "nao/robot_loop.hpp"
#include "nao/tools/arm_copy.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/evaluate.hpp"
#include "policy_stream.hpp"
#include "policy_train.hpp"
#include "train_select.hpp"
#include "support/random_policy.hpp"
#include "support/small_policy_data.hpp"
#include "support/test_util.hpp"
#include "support/torch_policy.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>
#include <torch/torch.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

using namespace nao;
using namespace nao::tools;

namespace {

const ArmModel& arm() {
  static const ArmModel a = loadArmModel(test::kUrdfPath);
  return a;
}

const SimModel& sim() {
  static const SimModel s = makeSimModel(arm());
  return s;
}

constexpr double kPeriod = 0.1;

// Key poses inside the limits (a net needs some; the step does not read them).
std::vector<std::vector<JointVector>> keyPoses(int movements, int k) {
  std::vector<std::vector<JointVector>> c(static_cast<std::size_t>(movements));
  for (int m = 0; m < movements; ++m)
    for (int i = 0; i < k; ++i)
      c[static_cast<std::size_t>(m)].push_back(clampToLimits(arm(), JointVector::Constant(0.1 * (i - m))));
  return c;
}

PolicyArch smallChunked() {
  PolicyArch a = smallArch();
  a.chunk = 10;
  return a;
}

struct ZeroClock final : ControllerClock {
  std::int64_t nowNs() override { return 0; }
};

}  // namespace

TEST_CASE("the torch streaming step equals the runtime's stepPolicy within 1e-5, 4 runs side by side over 3 windows") {
  torch::set_num_threads(1);
  torch::NoGradGuard no_grad;
  const PolicyArch arch = smallChunked();
  const PolicyNet net = test::perturbedNet(arch, Conditioning::kAutonomous, keyPoses(arch.movements, arch.clusters), 41);
  const std::vector<std::vector<float>> floats = manifestFloats(net);
  std::vector<const float*> p;
  for (const auto& f : floats) p.push_back(f.data());
  const PolicyWeights<SmallPolicyDims> weights =
      bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), arch, Conditioning::kAutonomous);
  const int n_runs = 4, ticks = 3 * arch.window + 3;
  std::mt19937_64 rng(5);
  const torch::Tensor z = torch::randn({n_runs, arch.d_model}) * 0.5;
  std::vector<std::unique_ptr<PolicyWorkspace<SmallPolicyDims>>> ws;
  for (int b = 0; b < n_runs; ++b) {
    ws.push_back(makePolicyWorkspace<SmallPolicyDims>());
    setPolicyRunCode(*ws.back(), z[b].contiguous().data_ptr<float>());
  }
  PolicyStream stream;
  torch::Tensor q = torch::empty({n_runs, kNumJoints});
  for (int b = 0; b < n_runs; ++b)
    for (int j = 0; j < kNumJoints; ++j) q[b][j] = test::uniformFloat(rng, arm().q_min[j], arm().q_max[j]);
  torch::Tensor a_prev = torch::zeros({n_runs, kNumJoints});
  const torch::Tensor movement = torch::tensor({0, 1, 2, 1}, torch::kInt64);
  double worst = 0.0, largest = 0.0;
  for (int t = 0; t < ticks; ++t) {
    StreamInput in;
    in.q = q;
    in.a_prev = a_prev;
    in.movement = movement;
    in.step = torch::full({n_runs}, t, torch::kInt64);
    in.z = z;
    const torch::Tensor a = streamStep(*net, stream, in).contiguous();
    for (int b = 0; b < n_runs; ++b) {
      PolicyInput x;
      for (int j = 0; j < kNumJoints; ++j) {
        x.q[j] = q[b][j].item<float>();
        x.a_prev[j] = a_prev[b][j].item<float>();
      }
      x.movement = static_cast<int>(movement[b].item<std::int64_t>());
      x.step = t;
      const auto& ref = stepPolicy(weights, *ws[static_cast<std::size_t>(b)], x);
      for (int j = 0; j < kNumJoints; ++j) {
        worst = std::max(worst, std::abs(static_cast<double>(ref[j]) - a[b][j].item<double>()));
        largest = std::max(largest, std::abs(static_cast<double>(ref[j])));
      }
    }
    // The next tick's inputs: a random walk, as a rollout's states.
    for (int b = 0; b < n_runs; ++b)
      for (int j = 0; j < kNumJoints; ++j) {
        a_prev[b][j] = test::uniformFloat(rng, -0.1, 0.1);
        q[b][j] = std::clamp(q[b][j].item<float>() + a_prev[b][j].item<float>(), static_cast<float>(arm().q_min[j]),
                             static_cast<float>(arm().q_max[j]));
      }
  }
  MESSAGE(n_runs << " runs x " << ticks << " ticks: worst |action difference| " << worst << " rad (largest action "
                 << largest << " rad)");
  CHECK(worst <= 1e-5);
  CHECK(largest > 1e-3);  // not vacuous
}

TEST_CASE("the torch streaming step equals the module's sequence forward (act) with its gradients flowing") {
  torch::set_num_threads(1);
  const PolicyArch arch = smallChunked();
  const PolicyNet net = test::perturbedNet(arch, Conditioning::kAutonomous, keyPoses(arch.movements, arch.clusters), 43);
  const int T = 2 * arch.window + 4;
  torch::manual_seed(3);
  const torch::Tensor q = torch::randn({2, T, kNumJoints}) * 0.3;
  const torch::Tensor a_prev = torch::randn({2, T, kNumJoints}) * 0.05;
  const torch::Tensor movement = torch::tensor({2, 0}, torch::kInt64);
  const torch::Tensor whole = net->act(q, a_prev, torch::zeros_like(q), movement);
  PolicyStream stream;
  std::vector<torch::Tensor> streamed;
  for (int t = 0; t < T; ++t) {
    StreamInput in;
    in.q = q.select(1, t);
    in.a_prev = a_prev.select(1, t);
    in.movement = movement;
    in.step = torch::full({2}, t, torch::kInt64);
    streamed.push_back(streamStep(*net, stream, in));
  }
  const torch::Tensor s = torch::stack(streamed, 1);
  const double worst = (s - whole).abs().max().item<double>();
  MESSAGE("worst |streamed - sequence| " << worst << " rad over " << T << " ticks");
  CHECK(worst <= 1e-5);
  // The same gradient for a loss on the last tick's action, through every layer's cache.
  const torch::Tensor w = torch::randn({2, kNumJoints});
  const auto grads = [&](const torch::Tensor& a) {
    for (torch::Tensor p : net->trainableParameters())
      if (p.grad().defined()) p.grad().zero_();
    (a.select(1, T - 1) * w).sum().backward({}, true);
    std::vector<torch::Tensor> g;
    for (const torch::Tensor& p : net->trainableParameters()) g.push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
    return g;
  };
  const std::vector<torch::Tensor> g_stream = grads(s), g_whole = grads(whole);
  double worst_grad = 0.0, largest_grad = 0.0;
  for (std::size_t i = 0; i < g_stream.size(); ++i) {
    worst_grad = std::max(worst_grad, (g_stream[i] - g_whole[i]).abs().max().item<double>());
    largest_grad = std::max(largest_grad, g_whole[i].abs().max().item<double>());
  }
  MESSAGE("worst |gradient difference| " << worst_grad << " (largest gradient " << largest_grad << ")");
  CHECK(worst_grad <= 1e-4 * std::max(1.0, largest_grad));
  CHECK(largest_grad > 1e-3);
}

TEST_CASE("the differentiable arm tick gives the copy's values and central-difference gradients") {
  torch::set_num_threads(1);
  std::mt19937_64 rng(9);
  const int n = 3, ticks = 4;
  torch::Tensor q0 = torch::empty({n, kNumJoints}, torch::kFloat64);
  for (int b = 0; b < n; ++b) {
    const JointVector p = test::randomPose(arm(), rng);
    for (int j = 0; j < kNumJoints; ++j) q0[b][j] = p[j];
  }
  const torch::Tensor actions = (torch::rand({ticks, n, kNumJoints}, torch::kFloat64) - 0.5) * 0.4;
  const torch::Tensor lo = q0 - 0.15, hi = q0 + 0.25;  // an envelope that cuts now and then
  const torch::Tensor w_q = torch::randn({n, kNumJoints}, torch::kFloat64), w_h = torch::randn({n, 3}, torch::kFloat64);
  // L = Σ over ticks of w_q·q + w_h·hand + w_q·a_applied: every output of the tick counts.
  const auto loss = [&](const torch::Tensor& a_all) {
    torch::Tensor q = q0, v = torch::zeros_like(q0), L = torch::zeros({}, torch::kFloat64);
    for (int t = 0; t < ticks; ++t) {
      const ArmTick k = armCopyTick(sim(), kPeriod, q, v, a_all[t], lo, hi);
      L = L + (k.q * w_q).sum() + (k.hand * w_h).sum() + (k.a_applied * w_q).sum();
      q = k.q;
      v = k.v;
    }
    return L;
  };
  // Values: run by run, the limiter and the copy themselves.
  {
    torch::NoGradGuard no_grad;
    const ArmTick k = armCopyTick(sim(), kPeriod, q0, torch::zeros_like(q0), actions[0], lo, hi);
    for (int b = 0; b < n; ++b) {
      JointVector q, a, q_cmd;
      JointEnvelope env;
      for (int j = 0; j < kNumJoints; ++j) {
        q[j] = q0[b][j].item<double>();
        a[j] = actions[0][b][j].item<double>();
        env.lo[j] = lo[b][j].item<double>();
        env.hi[j] = hi[b][j].item<double>();
      }
      limitCommand(arm(), kPeriod, q, a, q_cmd, &env);
      ArmCopyState s;
      s.q = q;
      stepArmCopy(sim(), s, q_cmd);
      ArmData kin;
      const Eigen::Vector3d hand = forwardKinematics(arm(), kin, s.q);
      for (int j = 0; j < kNumJoints; ++j) {
        CHECK(k.q[b][j].item<double>() == s.q[j]);
        CHECK(k.v[b][j].item<double>() == s.v[j]);
        CHECK(k.a_applied[b][j].item<double>() == q_cmd[j] - q[j]);
      }
      for (int r = 0; r < 3; ++r) CHECK(k.hand[b][r].item<double>() == hand[r]);
    }
  }
  torch::Tensor a = actions.clone().requires_grad_(true);
  loss(a).backward();
  const torch::Tensor g = a.grad();
  torch::NoGradGuard no_grad;
  const double h = 1e-7;
  int compared = 0, zero = 0;
  double worst = 0.0;
  for (int t = 0; t < ticks; ++t)
    for (int b = 0; b < n; ++b)
      for (int j = 0; j < kNumJoints; ++j) {
        torch::Tensor plus = actions.clone(), minus = actions.clone();
        plus[t][b][j] += h;
        minus[t][b][j] -= h;
        const double fd = (loss(plus).item<double>() - loss(minus).item<double>()) / (2 * h);
        const double ad = g[t][b][j].item<double>();
        worst = std::max(worst, std::abs(fd - ad) / (1.0 + std::abs(fd)));
        zero += ad == 0.0;
        ++compared;
      }
  MESSAGE(compared << " action entries: worst relative gradient error " << worst << ", " << zero << " cut by the limiter (0)");
  CHECK(worst <= 1e-4);
  CHECK(zero < compared);
}

TEST_CASE("an unroll through the torch stream and the arm copy follows nao_rt's controller on the ODE arm for 30 ticks") {
  torch::set_num_threads(1);
  torch::NoGradGuard no_grad;
  const PolicyArch arch = smallChunked();
  const PolicyNet net = test::perturbedNet(arch, Conditioning::kAutonomous, keyPoses(arch.movements, arch.clusters), 47);
  const std::vector<std::vector<float>> floats = manifestFloats(net);
  std::vector<const float*> p;
  for (const auto& f : floats) p.push_back(f.data());
  const PolicyWeights<SmallPolicyDims> weights =
      bindPolicyWeights<SmallPolicyDims>(p.data(), p.size(), arch, Conditioning::kAutonomous);
  // Three run codes per movement; a start picks one as the controller would.
  std::mt19937_64 rng(13);
  std::vector<ModelRunCodes> codes(static_cast<std::size_t>(arch.movements));
  for (ModelRunCodes& c : codes) {
    c.d = arch.d_model;
    for (int i = 0; i < 3; ++i) {
      c.names.push_back("demo_" + std::to_string(i));
      c.q.push_back(test::randomPose(arm(), rng));
      for (int k = 0; k < arch.d_model; ++k) c.code.push_back(test::uniformFloat(rng, -0.5, 0.5));
    }
    c.dtw_m = {0, 1, 2, 1, 0, 1.5, 2, 1.5, 0};
  }
  const int movement = 1, ticks = 30;
  const JointVector start = codes[1].q[2] + JointVector::Constant(0.02);
  std::vector<ModelWorkspace> workspace(static_cast<std::size_t>(arch.movements));
  for (ModelWorkspace& w : workspace) {
    w.lo = start.array() - 0.2;
    w.hi = start.array() + 0.2;
  }
  const ControllerModel<SmallPolicyDims> cm = configureController(arm(), weights, ControllerParams{}, workspace, codes);
  OdeArmBackend robot(arm(), SimParams{}, clampToLimits(arm(), start));
  ControllerData<SmallPolicyDims> data;
  ZeroClock clock;
  activateOnRobot(cm, data, robot, start, movement, clock);
  const int code = runCodeIndex(codes[1], clampToLimits(arm(), start));
  REQUIRE(code == data.run_code);
  // The torch unroll from the same start with the same code and envelope.
  const JointEnvelope env = cm.workspace[static_cast<std::size_t>(movement)];
  torch::Tensor q = torch::empty({1, kNumJoints}, torch::kFloat64), lo = torch::empty_like(q), hi = torch::empty_like(q);
  const JointVector q0 = clampToLimits(arm(), start);
  for (int j = 0; j < kNumJoints; ++j) {
    q[0][j] = q0[j];
    lo[0][j] = env.lo[j];
    hi[0][j] = env.hi[j];
  }
  torch::Tensor v = torch::zeros_like(q), a_prev = torch::zeros({1, kNumJoints});
  const torch::Tensor z =
      torch::from_blob(const_cast<float*>(codes[1].code.data()) + static_cast<std::ptrdiff_t>(code) * arch.d_model,
                       {1, arch.d_model})
          .clone();
  PolicyStream stream;
  double worst = 0.0, travelled = 0.0;
  int enveloped = 0;
  for (int t = 0; t < ticks; ++t) {
    StreamInput in;
    in.q = q.to(torch::kFloat32);
    in.a_prev = a_prev;
    in.movement = torch::tensor({movement}, torch::kInt64);
    in.step = torch::tensor({t}, torch::kInt64);
    in.z = z;
    const ArmTick k = armCopyTick(sim(), kPeriod, q, v, streamStep(*net, stream, in), lo, hi);
    const TickRecord& rec = runControllerTick(cm, data, robot, nullptr);
    enveloped += (rec.fault & kFaultOutsideWorkspace) != 0;
    for (int j = 0; j < kNumJoints; ++j) {
      worst = std::max(worst, std::abs(rec.q[j] - k.q[0][j].item<double>()));
      travelled = std::max(travelled, std::abs(rec.q[j] - q0[j]));
    }
    q = k.q;
    v = k.v;
    a_prev = k.a_applied.to(torch::kFloat32);
  }
  MESSAGE(ticks << " ticks: worst |q difference| " << worst << " rad; the arm moved up to " << travelled
                << " rad; the envelope cut " << enveloped << " tick(s)");
  CHECK(worst <= 1e-3);
  CHECK(travelled > 0.05);  // not vacuous: the net moved the arm
}

TEST_CASE("the closed-loop loss of a run is its hand and joint error against the replay, and its gradient reaches the net") {
  torch::set_num_threads(1);
  const PolicyData& data = test::smallData();
  PolicyArch arch = smallChunked();
  arch.movements = data.movements();
  arch.clusters = data.clusters();
  torch::manual_seed(1);
  PolicyNet net(arch, Conditioning::kAutonomous);
  // The executed sequences the run codes index (clean rollouts only: one per demonstration).
  std::vector<int> all;
  for (std::size_t i = 0; i < data.demos.size(); ++i) all.push_back(static_cast<int>(i));
  ExecutionOptions e;
  e.noisy_rollouts = 0;
  const std::vector<PolicySequence> seqs = executeDemos(data, all, sim(), e, 1);
  net->setNormalisation(normStats(seqs));
  const SequenceTensors train = toTensors(net, seqs);
  const RunCodeSource source = runCodeSource(data, seqs, arm(), arch.d_model);
  const ClosedLoopData cl = closedLoopData(data, source, sim(), kPeriod, ControllerParams{}.workspace_margin_rad);
  REQUIRE(cl.own.size() == data.demos.size());
  // A run's target begins at its start and is the replay of the code's demonstration.
  const ClosedLoopRun& run = cl.own.front();
  CHECK(run.q.front() == clampToLimits(arm(), data.demos[static_cast<std::size_t>(run.source)].start));
  CHECK(static_cast<int>(run.q.size()) == run.ticks + 1);
  RunLatent latent(4, arch.d_model);
  ClosedLoopOptions o;
  const std::vector<const ClosedLoopRun*> runs = {&cl.own[0], &cl.own[5]};
  const ClosedLoopLoss l = closedLoopLoss(*net, latent.get(), train, cl, sim(), kPeriod, runs, 0, 12, o);
  CHECK(l.ticks == 24);
  // A segment from tick 20 after the target's own 20 ticks: 12 ticks each again.
  const ClosedLoopLoss later = closedLoopLoss(*net, latent.get(), train, cl, sim(), kPeriod, runs, 20, 12, o);
  CHECK(later.ticks == 24);
  CHECK(later.loss.item<double>() != l.loss.item<double>());
  CHECK(std::isfinite(l.loss.item<double>()));
  CHECK(l.loss.item<double>() >= 1e4 * l.hand_sse_m2 * o.hand_weight);  // the hand term is part of it
  l.loss.backward();
  double head = 0.0, code = 0.0;
  head = net->head_chunk->weight.grad().abs().sum().item<double>();
  for (const torch::Tensor& t : latent->parameters()) code += t.grad().defined() ? t.grad().abs().sum().item<double>() : 0.0;
  CHECK(head > 0.0);
  CHECK(code > 0.0);  // the run code is trained through the rollout too
  // The epoch's runs: own starts, perturbed and between, each with its code's replay.
  const std::vector<ClosedLoopRun> epoch_runs = closedLoopEpochRuns(data, cl, sim(), kPeriod, o, 1, 1);
  CHECK(epoch_runs.size() == 3 * data.demos.size());
  const std::vector<ClosedLoopRun> again = closedLoopEpochRuns(data, cl, sim(), kPeriod, o, 1, 1);
  for (std::size_t i = 0; i < epoch_runs.size(); ++i) CHECK(epoch_runs[i].start == again[i].start);
  CHECK((epoch_runs[data.demos.size()].start - epoch_runs[0].start).norm() > 0.0);
}

TEST_CASE("closed-loop training: deterministic, another result than teacher forcing alone, resumable from a teacher-forced checkpoint, recorded, refused where it means nothing") {
  torch::set_num_threads(1);
  TrainOptions tf = test::smallOptions(91, 2);
  tf.conditioning = Conditioning::kAutonomous;
  tf.latent_dims = 4;
  tf.arch.chunk = 3;
  TrainOptions o = tf;
  o.closed_loop.epochs = 2;
  o.closed_loop.batch = 4;
  o.closed_loop.horizon = 10;
  o.closed_loop.horizon_growth = 5;
  o.closed_loop.lr = 5e-4;
  TrainResult r;
  const std::vector<std::uint8_t> a = test::trainBytes(o, &r), teacher = test::trainBytes(tf);
  CHECK_MESSAGE(a == test::trainBytes(o), "two closed-loop runs with one seed gave different bytes");
  REQUIRE(r.history.size() == 4);
  CHECK(std::isnan(r.history[1].closed_loop_hand_rms_m));
  for (int e = 2; e < 4; ++e) {
    const EpochStats& st = r.history[static_cast<std::size_t>(e)];
    CHECK(std::isfinite(st.closed_loop_hand_rms_m));
    for (const double k : st.closed_loop_kind_rms_m) CHECK(std::isfinite(k));
    // Every run, own start, perturbed and between, segments of 10 then 15 ticks (the runs are longer).
    const std::size_t runs = 3 * r.split.train.size();
    CHECK(st.samples == runs * static_cast<std::size_t>(e == 2 ? 10 : 15));
  }
  // A closed-loop run keeps one of its closed-loop epochs, and they moved the weights.
  CHECK(r.best_epoch > 2);
  CHECK_MESSAGE(a != teacher, "the closed-loop epochs changed nothing");
  const nlohmann::json meta = nlohmann::json::parse(decodeModel(a, "cl.bin").header.metadata_json)["training"];
  CHECK(meta["closed_loop"]["epochs"] == 2);
  CHECK(meta["closed_loop"]["horizon"] == 10);
  CHECK(modelCard(test::smallData(), o, r, "cmd", "m.bin").find("| closed loop | after the 2 teacher-forced epochs, 2 epochs") !=
        std::string::npos);

  // The teacher-forced epochs checkpointed alone, then the closed-loop run resumed from them: the
  // same bytes as the run straight through.
  const std::string dir = (std::filesystem::temp_directory_path() / "nao_rt_tests").string();
  std::filesystem::create_directories(dir);
  const std::string ck = dir + "/closed_loop_checkpoint_" + std::to_string(::getpid()) + ".pt";
  TrainOptions first = tf;
  first.checkpoint = ck;
  trainPolicy(test::smallData(), test::smallSim(), first, nullptr);
  TrainOptions rest = o;
  rest.resume = ck;
  rest.checkpoint = ck + ".cl";
  TrainResult resumed;
  CHECK_MESSAGE(test::trainBytes(rest, &resumed) == a, "resumed after the teacher-forced epochs, the bytes differ");
  CHECK(resumed.resumed_after == 2);
  // A checkpoint of the closed-loop phase belongs to its options: another learning rate is refused.
  TrainOptions other = o;
  other.closed_loop.lr = 1e-3;
  other.resume = ck + ".cl";
  CHECK_THROWS_AS(trainPolicy(test::smallData(), test::smallSim(), other, nullptr), UserError);
  std::filesystem::remove(ck);
  std::filesystem::remove(ck + ".cl");

  TrainOptions reference = o;
  reference.conditioning = Conditioning::kReference;
  reference.latent_dims = 0;
  CHECK_THROWS_WITH_AS(trainPolicy(test::smallData(), test::smallSim(), reference, nullptr), doctest::Contains("autonomous"),
                       UserError);
}

TEST_CASE("selection by code fidelity: a run that is its code's demonstration plays it at 0 mm; the epoch in range that plays closest wins") {
  const PolicyData& data = test::smallData();
  const std::vector<int> val = {1, 5, 9};
  std::vector<int> train;
  for (std::size_t i = 0; i < data.demos.size(); ++i)
    if (std::find(val.begin(), val.end(), static_cast<int>(i)) == val.end()) train.push_back(static_cast<int>(i));
  ExecutionOptions e;
  e.noisy_rollouts = 0;
  const std::vector<PolicySequence> seqs = executeDemos(data, train, sim(), e, 1);
  const RunCodeSource source = runCodeSource(data, seqs, arm(), 8);
  const SelectionReference ref = selectionReference(data, val, arm(), kPeriod, &source.codes);
  REQUIRE(ref.code_paths.size() == 3);
  // Each validation start's run is the demonstration its code names, started where that one did.
  std::vector<PolicyRun> runs;
  for (const int d : val) {
    const int m = data.demos[static_cast<std::size_t>(d)].movement;
    const int code = runCodeIndex(source.codes[static_cast<std::size_t>(m)], data.demos[static_cast<std::size_t>(d)].f.front());
    REQUIRE(code >= 0);
    const std::string& name = source.codes[static_cast<std::size_t>(m)].names[static_cast<std::size_t>(code)];
    const auto played = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& x) { return x.name == name; });
    std::vector<JointVector> q = played->f;
    q.front() = data.demos[static_cast<std::size_t>(d)].f.front();  // the code is chosen from the run's start
    runs.push_back({d, m, q, {}});
  }
  EpochStats faithful;
  scoreRuns(runs, ref, arm(), kPeriod, faithful, &source.codes);
  for (const MovementScore& s : faithful.rollouts) CHECK(s.code_fidelity_m < 0.01);
  CHECK(std::isfinite(faithful.code_fidelity_m));
  EpochStats no_codes;
  scoreRuns(runs, ref, arm(), kPeriod, no_codes);
  CHECK(std::isnan(no_codes.code_fidelity_m));
  // The ranking: finite over NaN, in range over out of range, then the lower fidelity; the
  // nearest-demonstration DTW does not decide.
  EpochStats close = faithful, far = faithful, wild = faithful;
  close.code_fidelity_m = 0.004;
  close.rollout_dtw_m = 0.03;
  far.code_fidelity_m = 0.009;
  far.rollout_dtw_m = 0.01;
  wild.code_fidelity_m = 0.001;
  wild.rollouts[0].range_excess_rad = 0.2;
  CHECK(betterEpoch(close, far, true));
  CHECK_FALSE(betterEpoch(far, close, true));
  CHECK(betterEpoch(far, close, false));  // by DTW to the nearest held-out demonstration, the other way
  CHECK(betterEpoch(close, wild, true));
  CHECK(betterEpoch(far, no_codes, true));
  CHECK_FALSE(betterEpoch(no_codes, far, true));
}

namespace {

// The closed-loop data of smallData() with every demonstration as a training one (clean rollouts).
struct ClosedLoopFixture {
  std::vector<PolicySequence> seqs;
  RunCodeSource source;
  ClosedLoopData cl;
  SequenceTensors train;
  PolicyNet net{nullptr};
};
ClosedLoopFixture closedLoopFixture() {
  const PolicyData& data = test::smallData();
  ClosedLoopFixture f;
  PolicyArch arch = smallChunked();
  arch.movements = data.movements();
  arch.clusters = data.clusters();
  torch::manual_seed(1);
  f.net = PolicyNet(arch, Conditioning::kAutonomous);
  std::vector<int> all;
  for (std::size_t i = 0; i < data.demos.size(); ++i) all.push_back(static_cast<int>(i));
  ExecutionOptions e;
  e.noisy_rollouts = 0;
  f.seqs = executeDemos(data, all, sim(), e, 1);
  f.net->setNormalisation(normStats(f.seqs));
  f.train = toTensors(f.net, f.seqs);
  f.source = runCodeSource(data, f.seqs, arm(), arch.d_model);
  f.cl = closedLoopData(data, f.source, sim(), kPeriod, ControllerParams{}.workspace_margin_rad);
  return f;
}

}  // namespace

TEST_CASE("the trainer pairs every start with the runtime's code: runCodeIndex with the start's own demonstration left out") {
  const PolicyData& data = test::smallData();
  const ClosedLoopFixture f = closedLoopFixture();
  const std::vector<ModelRunCodes>& codes = f.source.codes;
  int differs_from_own_rule = 0;
  // Every training start (its own demonstration's), then the closed loop's other starts.
  REQUIRE(f.cl.own.size() == data.demos.size());
  for (const ClosedLoopRun& own : f.cl.own) {
    const ModelRunCodes& c = codes[static_cast<std::size_t>(own.movement)];
    REQUIRE(c.names[static_cast<std::size_t>(own.source_code)] == data.demos[static_cast<std::size_t>(own.source)].name);
    CHECK(own.start == clampToLimits(arm(), data.demos[static_cast<std::size_t>(own.source)].start));
    CHECK(own.code == runCodeIndex(c, own.start, own.source_code));
    CHECK(own.code != own.source_code);  // a training start is nobody's start: not its own code
    differs_from_own_rule += own.code != runCodeIndex(c, own.start);
  }
  MESSAGE(differs_from_own_rule << " of " << f.cl.own.size()
                                << " training starts take another code with their own demonstration left out");
  ClosedLoopOptions o;
  o.starts = 4;
  for (const ClosedLoopRun& r : closedLoopEpochRuns(data, f.cl, sim(), kPeriod, o, 1, 3))
    CHECK(r.code == runCodeIndex(codes[static_cast<std::size_t>(r.movement)], r.start, r.source_code));
}

TEST_CASE("whole runs: every run's segment lies in its own length and reaches its end; per-run starts give each run its loss alone") {
  ClosedLoopFixture f = closedLoopFixture();
  // Segment starts of a run of n ticks: within 0 .. n − horizon, both ends drawn.
  const ClosedLoopRun& longest = *std::max_element(f.cl.own.begin(), f.cl.own.end(),
                                                   [](const ClosedLoopRun& a, const ClosedLoopRun& b) { return a.ticks < b.ticks; });
  const ClosedLoopRun& shortest = *std::min_element(f.cl.own.begin(), f.cl.own.end(),
                                                    [](const ClosedLoopRun& a, const ClosedLoopRun& b) { return a.ticks < b.ticks; });
  REQUIRE(longest.ticks > shortest.ticks);
  const int horizon = 12;
  int lowest = longest.ticks, highest = -1;
  for (std::uint64_t key = 0; key < 4000; ++key) {
    const int s = closedLoopRunSegmentStart(longest, horizon, key);
    lowest = std::min(lowest, s);
    highest = std::max(highest, s);
  }
  CHECK(lowest == 0);
  CHECK(highest == longest.ticks - horizon);  // its last tick is rolled
  CHECK(highest > shortest.ticks - horizon);  // past where a batch's shortest run would stop it
  CHECK(closedLoopRunSegmentStart(shortest, shortest.ticks + 5, 7) == 0);

  // Two runs with segments of their own in one batch: each run's loss, ticks and gradient are
  // those it has alone; equal starts are the single-start loss exactly.
  ClosedLoopOptions o;
  RunLatent latent(4, f.net->arch().d_model);
  const std::vector<const ClosedLoopRun*> both = {&shortest, &longest};
  const std::vector<int> starts = {3, longest.ticks - horizon};
  const auto gradOf = [&](const torch::Tensor& loss) {
    for (torch::Tensor& p : f.net->parameters())
      if (p.grad().defined()) p.mutable_grad().zero_();
    for (torch::Tensor& p : latent->parameters())
      if (p.grad().defined()) p.mutable_grad().zero_();
    loss.backward();
    return f.net->head_chunk->weight.grad().clone();
  };
  const ClosedLoopLoss together = closedLoopLoss(*f.net, latent.get(), f.train, f.cl, sim(), kPeriod, both, starts, horizon, o);
  const torch::Tensor g_together = gradOf(together.loss);
  CHECK(together.ticks == 2 * horizon);
  double alone_loss = 0.0;
  torch::Tensor g_alone = torch::zeros_like(g_together);
  for (std::size_t b = 0; b < 2; ++b) {
    const ClosedLoopLoss l = closedLoopLoss(*f.net, latent.get(), f.train, f.cl, sim(), kPeriod, {both[b]}, starts[b], horizon, o);
    CHECK(l.ticks == horizon);
    CHECK(together.run_hand_sse_m2[b] == doctest::Approx(l.hand_sse_m2).epsilon(1e-9));
    alone_loss += l.loss.item<double>();
    g_alone += gradOf(l.loss);
  }
  CHECK(together.loss.item<double>() == doctest::Approx(alone_loss).epsilon(1e-9));
  const double g_scale = g_alone.abs().max().item<double>();
  REQUIRE(g_scale > 0.0);
  CHECK((g_together - g_alone).abs().max().item<double>() <= 1e-6 * g_scale);
  const ClosedLoopLoss same = closedLoopLoss(*f.net, latent.get(), f.train, f.cl, sim(), kPeriod, both, std::vector<int>{3, 3}, horizon, o);
  const ClosedLoopLoss single = closedLoopLoss(*f.net, latent.get(), f.train, f.cl, sim(), kPeriod, both, 3, horizon, o);
  CHECK(same.loss.item<double>() == single.loss.item<double>());
  CHECK(same.ticks == single.ticks);
}

TEST_CASE("selection's speed against the replay: a run that is its medoid replay moves at exactly 1") {
  const PolicyData& data = test::smallData();
  const std::vector<int> val = {1, 5, 9};
  std::vector<int> train;
  for (std::size_t i = 0; i < data.demos.size(); ++i)
    if (std::find(val.begin(), val.end(), static_cast<int>(i)) == val.end()) train.push_back(static_cast<int>(i));
  ExecutionOptions e;
  e.noisy_rollouts = 0;
  const RunCodeSource source = runCodeSource(data, executeDemos(data, train, sim(), e, 1), arm(), 8);
  SelectionReference ref = selectionReference(data, val, arm(), kPeriod, &source.codes);
  EpochStats plain;
  std::vector<PolicyRun> runs;
  for (const int d : val) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    const JointVector start = clampToLimits(arm(), demo.start);
    const ModelRunCodes& c = source.codes[static_cast<std::size_t>(demo.movement)];
    const std::string& name = c.names[static_cast<std::size_t>(runCodeIndex(c, start))];
    const auto played = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& x) { return x.name == name; });
    runs.push_back({d, demo.movement,
                    trackDemo(sim(), kPeriod, servoStepGain(sim().params), played->f, start, static_cast<int>(demo.f.size()) - 1),
                    {}});
  }
  scoreRuns(runs, ref, arm(), kPeriod, plain, &source.codes);
  for (const MovementScore& s : plain.rollouts) CHECK(std::isnan(s.speed_vs_replay));  // not asked for
  addReplaySpeeds(ref, data, val, sim(), kPeriod, source.codes);
  REQUIRE(ref.replay_speed.size() == data.demos.size());
  CHECK(std::isnan(ref.replay_speed[0]));  // a training demonstration has none
  EpochStats st;
  scoreRuns(runs, ref, arm(), kPeriod, st, &source.codes);
  int other = 0;
  for (const MovementScore& s : st.rollouts) {
    CHECK(s.speed_vs_replay == 1.0);
    other += std::abs(s.speed_ratio - 1.0) > 1e-3;  // against the held-out demonstrations it is not 1
  }
  CHECK(other > 0);
}
