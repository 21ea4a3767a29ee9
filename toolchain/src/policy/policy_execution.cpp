// Executing demonstrations on the simulated arm (docs/policy.md "Data"): the expert that labels
// every tick with the command ending it on f(t+1), the clean and noisy executions of the training
// data, and a policy's runs from the demonstrations' starts.
#include "nao/tools/command.hpp"
#include "nao/robot_backend.hpp"
#include "nao/rollout.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/tools/splitmix.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <mutex>
#include <ostream>
#include <thread>

namespace nao::tools {
namespace {

// The control period of the simulated arm: SimParams::substeps_per_tick physics steps.
double tickPeriod(const SimModel& sim_model) { return sim_model.params.dt_s * sim_model.params.substeps_per_tick; }

// The controller's per-tick command bounds at q (rollout.hpp): the position limits and one
// period's reach.
void commandBounds(const SimModel& sim_model, const JointVector& q, JointVector& lo, JointVector& hi) {
  nao::commandBounds(sim_model.arm, tickPeriod(sim_model), q, lo, hi);
}

// The expert of ExecutionOptions: the command in [lo, hi] for which the arm, from the state in
// `snap`, ends the tick nearest `target`. Per-joint secant steps on the end-of-tick angle (the
// servo moves each joint mostly on its own; the iterations absorb the coupling); returns the
// best command tried. Leaves `sim` in the state of `snap`.
JointVector expertCommand(const SimModel& model, SimData& sim, const SimSnapshot& snap, const JointVector& target,
                          const JointVector& lo, const JointVector& hi, const ExecutionOptions& o, double& miss) {
  const auto clampTo = [&](JointVector c) {
    for (int j = 0; j < kNumJoints; ++j) c[j] = std::clamp(c[j], lo[j], hi[j]);
    return c;
  };
  const auto endOf = [&](const JointVector& c) {
    restoreSim(sim, snap);
    return JointVector(stepSim(model, sim, c));
  };
  JointVector c_prev = clampTo(target);
  JointVector e_prev = target - endOf(c_prev);
  JointVector best = c_prev;
  double best_miss = e_prev.cwiseAbs().maxCoeff();
  // First step: the first-order servo inversion.
  const double first_gain = servoStepGain(model.params);
  JointVector c = clampTo(c_prev + first_gain * e_prev);
  for (int it = 0; it < o.expert_iterations && best_miss > o.expert_tol_rad; ++it) {
    const JointVector e = target - endOf(c);
    const double m = e.cwiseAbs().maxCoeff();
    if (m < best_miss) {
      best_miss = m;
      best = c;
    }
    JointVector next = c;
    for (int j = 0; j < kNumJoints; ++j) {
      const double de = e_prev[j] - e[j], dc = c[j] - c_prev[j];
      // Secant on e(c) = target − q_end(c); fall back to the first-order gain when flat.
      const double slope = std::abs(de) > 1e-12 && std::abs(dc) > 1e-12 ? dc / de : first_gain;
      next[j] = c[j] + std::clamp(slope, 0.5, 4.0) * e[j];
    }
    c_prev = c;
    e_prev = e;
    c = clampTo(next);
  }
  restoreSim(sim, snap);
  miss = best_miss;
  return best;
}

// Rollout k of demonstration d (see executeDemos), on `sim` (any state; reset here). The inputs
// are what the controller sees: q(t), the applied a(t−1), and r = f(t+1) − q(t), the offset of
// the tick's feature-extracted target (computed online by the controller from the snapped key
// poses) - as a difference: in normalised units the label needs r − q to ~1e-3 of the angles'
// spread, which the net learnt only slowly as f(t+1) itself.
PolicySequence executeRollout(const PolicyData& data, int d, int k, const SimModel& sim_model, SimData& sim,
                              const ExecutionOptions& o, std::uint64_t seed, const std::vector<int>& same_movement) {
  const PolicyDemo& demo = data.demos.at(static_cast<std::size_t>(d));
  PolicySequence s;
  s.demo = d;
  s.movement = demo.movement;
  s.rollout = k;
  const double sd = k == 0 ? 0.0 : kNoiseStdRad[static_cast<std::size_t>(k - 1) % kNoiseStdRad.size()];
  SplitMix64 rng(seed ^ (0x9e3779b97f4a7c15ull * static_cast<std::uint64_t>(d + 1)) ^
                 (0xc2b2ae3d27d4eb4full * static_cast<std::uint64_t>(k + 1)));
  const auto normal = [&] {
    const double u1 = rng.uniform();  // two statements: the order of draws is fixed
    const double u2 = rng.uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  };
  SimSnapshot snap;
  JointVector start = demo.f.front();
  if (k > 0 && o.other_starts) {
    // Another listed demonstration of the movement (its own start if it is the only one).
    std::vector<int> others;
    for (int e : same_movement)
      if (e != d) others.push_back(e);
    if (!others.empty()) {
      const auto pick = static_cast<std::size_t>(rng.uniform() * static_cast<double>(others.size())) % others.size();
      start = data.demos[static_cast<std::size_t>(others[pick])].f.front();
    }
  }
  resetSim(sim_model, sim, start);
  JointVector q = sim.q, a_prev = JointVector::Zero(), noise = JointVector::Zero();
  const double innovation = sd * std::sqrt(1.0 - o.noise_corr * o.noise_corr);
  for (std::size_t t = 0; t + 1 < demo.f.size(); ++t) {
    JointVector lo, hi;
    double miss = 0.0;
    const JointVector target = clampToLimits(sim_model.arm, demo.f[t + 1]);
    commandBounds(sim_model, q, lo, hi);
    captureSim(sim, snap);
    const JointVector c = expertCommand(sim_model, sim, snap, target, lo, hi, o, miss);
    s.q.push_back(q);
    s.a_prev.push_back(a_prev);
    s.r.push_back(target - q);
    s.a.push_back(c - q);
    if (k == 0) s.worst_miss_rad = std::max(s.worst_miss_rad, miss);
    JointVector c_exec = c;
    if (k > 0) {
      for (int j = 0; j < kNumJoints; ++j) noise[j] = o.noise_corr * noise[j] + innovation * normal();
      c_exec += noise;
      for (int j = 0; j < kNumJoints; ++j) c_exec[j] = std::clamp(c_exec[j], lo[j], hi[j]);
    }
    a_prev = c_exec - q;
    q = stepSim(sim_model, sim, c_exec);
  }
  return s;
}

void checkDemos(const PolicyData& data, const std::vector<int>& demos) {
  for (int d : demos)
    if (d < 0 || static_cast<std::size_t>(d) >= data.demos.size())
      throw UserError("execution: demonstration index " + std::to_string(d) + " is out of range");
}

void checkExecution(const PolicyData& data, const std::vector<int>& demos, const ExecutionOptions& o) {
  if (o.noisy_rollouts < 0) throw UserError("execution: noisy_rollouts must not be negative");
  if (!(o.noise_corr >= 0.0 && o.noise_corr < 1.0)) throw UserError("execution: noise_corr must be in [0, 1)");
  if (o.expert_iterations < 1) throw UserError("execution: expert_iterations must be at least 1");
  if (o.threads < 1) throw UserError("execution: threads must be at least 1");
  checkDemos(data, demos);
}

}  // namespace

std::vector<PolicySequence> executeDemos(const PolicyData& data, const std::vector<int>& demos,
                                         const SimModel& sim_model, const ExecutionOptions& o, std::uint64_t seed,
                                         std::ostream* progress) {
  checkExecution(data, demos, o);
  const std::size_t per_demo = static_cast<std::size_t>(1 + o.noisy_rollouts);
  const std::size_t total = demos.size() * per_demo;
  std::vector<PolicySequence> out(total);
  std::vector<std::vector<int>> by_movement(static_cast<std::size_t>(data.movements()));
  for (int d : demos) by_movement[static_cast<std::size_t>(data.demos[static_cast<std::size_t>(d)].movement)].push_back(d);
  // Rollouts are independent (own seed stream, reset arm): threads take them in turn and each
  // result goes to its own slot, so the output does not depend on the thread count.
  std::atomic<std::size_t> next{0}, done{0};
  std::mutex report;
  std::size_t reported = 0;
  std::exception_ptr failure;
  const auto work = [&] {
    try {
      SimData sim(sim_model, JointVector::Zero());  // ODE data per thread: built on this thread
      for (std::size_t i = next++; i < total; i = next++) {
        const int d = demos[i / per_demo];
        out[i] = executeRollout(data, d, static_cast<int>(i % per_demo), sim_model, sim, o, seed,
                                by_movement[static_cast<std::size_t>(data.demos[static_cast<std::size_t>(d)].movement)]);
        const std::size_t n = ++done;
        if (progress) {
          const std::lock_guard<std::mutex> lock(report);
          if (n * 10 / total > reported) {
            reported = n * 10 / total;
            *progress << "executed " << n << "/" << total << " rollouts" << std::endl;
          }
        }
      }
    } catch (...) {
      const std::lock_guard<std::mutex> lock(report);
      if (!failure) failure = std::current_exception();
      next = total;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < o.threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
  return out;
}

std::vector<PolicyRun> rolloutPolicy(const PolicyData& data, const std::vector<int>& demos, const SimModel& sim_model,
                                     const RolloutPolicy& policy, const std::vector<JointEnvelope>* workspace) {
  checkDemos(data, demos);
  if (!policy) throw UserError("execution: no policy to roll out");
  const ArmModel& arm = sim_model.arm;
  std::vector<PolicyRun> out;
  out.reserve(demos.size());
  SimData sim(sim_model, JointVector::Zero());
  OdeArmBackend robot(sim_model, sim);
  CommandStep step;
  for (int d : demos) {
    const PolicyDemo& demo = data.demos[static_cast<std::size_t>(d)];
    PolicyRun run;
    run.demo = d;
    run.movement = demo.movement;
    resetSim(sim_model, sim, demo.f.front());
    JointVector q = sim.q, a_prev = JointVector::Zero();
    run.q.push_back(q);
    for (std::size_t t = 0; t + 1 < demo.f.size(); ++t) {
      const JointVector r = clampToLimits(arm, demo.f[t + 1]) - q;
      // The controller's command, with the autonomous workspace envelope where given; a
      // non-finite action holds and is recorded as 0 (kFaultPolicyNonFinite).
      q = rolloutStep(arm, tickPeriod(sim_model), robot, policy(demo.movement, static_cast<int>(t), q, a_prev, r),
                      step, workspace == nullptr ? nullptr : &(*workspace)[static_cast<std::size_t>(demo.movement)]);
      run.a.push_back(step.a);
      a_prev = step.a_applied;
      run.q.push_back(q);
    }
    out.push_back(std::move(run));
  }
  return out;
}

}  // namespace nao::tools
