// nao_rt: the NAO arm controller runtime.
//
// This stage drives the ODE-simulated arm through a scripted motion (key poses joined
// smoothly) on the 10 Hz tick grid and reports where the hand went against where the
// commanded pose puts it. The imitation policy and the human reference sources plug into
// the same loop in later stages (DESIGN section 9).
#include "nao/arm_model.hpp"
#include "nao/kinematics.hpp"
#include "nao/sim_arm.hpp"
#include "rt_info.hpp"

#if NAO_HAVE_COMPILED_MODEL
#include "nao/compiled_model.hpp"
#endif

#include <CLI/CLI.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <vector>

namespace {

constexpr double kTickS = 0.1;

// Key poses of the scripted motion (rad, joint order RShoulderPitch .. RWristYaw), each
// reached after kSegmentS seconds of smoothstep blending from the previous one.
constexpr double kSegmentS = 2.0;
constexpr std::array<std::array<double, nao::kNumJoints>, 6> kKeyPoses = {{
    {1.40, -0.20, 1.20, 0.50, 0.00},    // NAO's rest pose: arm down, elbow slightly bent
    {0.00, -0.30, 0.00, 0.10, 0.00},    // reach straight forward
    {0.00, -1.20, 0.00, 0.10, 0.00},    // swing out to the side
    {-1.20, -0.30, 1.00, 1.20, 0.80},   // raise, bend the elbow, turn the wrist
    {0.50, 0.20, -1.00, 1.40, -0.80},   // across the body, elbow fully bent
    {1.40, -0.20, 1.20, 0.50, 0.00},    // back to rest
}};

nao::JointVector scriptedCommand(double t_s) {
  const double total = kSegmentS * (kKeyPoses.size() - 1);
  const double t = std::min(std::max(t_s, 0.0), total);
  const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(t / kSegmentS), kKeyPoses.size() - 2);
  const double s = (t - kSegmentS * static_cast<double>(k)) / kSegmentS;
  const double w = s * s * (3.0 - 2.0 * s);
  nao::JointVector q;
  for (int j = 0; j < nao::kNumJoints; ++j) q[j] = (1.0 - w) * kKeyPoses[k][j] + w * kKeyPoses[k + 1][j];
  return q;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "nao_rt: NAO V6 right-arm controller runtime on the ODE-simulated arm.\n"
      "Runs the 10 Hz control loop (100 x 1 ms physics substeps per tick) and reports where the\n"
      "hand went. Reference source available in this build: 'scripted' (key poses: rest, reach\n"
      "forward, out to the side, raise with elbow bent, across the body, rest)."};
  std::string urdf_path = NAO_DEFAULT_URDF;
  std::string reference = "scripted";
  int ticks = 0;
  double seconds = 0.0;
  std::string csv_path;
  double gain = nao::SimParams{}.servo_gain_per_s;
  app.add_option("--urdf", urdf_path, "Robot description (torso + right arm)")->capture_default_str();
  app.add_option("--reference", reference, "Reference source")->check(CLI::IsMember({"scripted"}))->capture_default_str();
  auto* ticks_opt = app.add_option("--ticks", ticks, "Number of 100 ms ticks to run (default: the whole script)")
                        ->check(CLI::PositiveNumber);
  app.add_option("--seconds", seconds, "Run time in seconds, rounded to whole ticks")
      ->check(CLI::PositiveNumber)
      ->excludes(ticks_opt);
  app.add_option("--csv", csv_path, "Write one line per tick (command, joint angles, hand positions) to this file");
  app.add_option("--servo-gain", gain, "Servo gain K of the simulated position servos, 1/s")
      ->check(CLI::Range(1.0, 500.0))
      ->capture_default_str();
  bool info = false;
  std::string weights_path;
  auto* info_flag = app.add_flag("--info", info,
                                 "Check the policy model (compiled-in, or --weights) against the URDF, print it as "
                                 "one JSON object and exit");
  app.add_option("--weights", weights_path, "model.bin to use instead of the compiled-in model")->needs(info_flag);
  CLI11_PARSE(app, argc, argv);

  if (info) {
    nao::rt::InfoOptions options;
    options.weights_path = weights_path;
    options.urdf_path = urdf_path;
#if NAO_HAVE_COMPILED_MODEL
    const nao::compiled::ModelBytes compiled = nao::compiled::modelBytes();
    options.compiled = compiled.data;
    options.compiled_size = compiled.size;
#endif
    return nao::rt::runInfo(options, std::cout, std::cerr);
  }

  const int script_ticks = static_cast<int>(std::lround(kSegmentS * (kKeyPoses.size() - 1) / kTickS)) + 10;
  const int n_ticks = ticks > 0 ? ticks : seconds > 0.0 ? static_cast<int>(std::lround(seconds / kTickS)) : script_ticks;

  // Configure: everything that can fail or allocate happens here, before the loop.
  nao::ArmModel arm;
  try {
    arm = nao::loadArmModel(urdf_path);
  } catch (const std::exception& e) {
    std::cerr << "nao_rt: " << e.what() << "\n";
    return 2;
  }
  nao::SimParams params;
  params.servo_gain_per_s = gain;
  const nao::SimModel sim_model = nao::makeSimModel(arm, params);
  const nao::JointVector q0 = scriptedCommand(0.0);
  nao::SimData sim(sim_model, q0);
  nao::ArmData kin;

  // Open the log now so a bad path fails before the run, not after it.
  std::ofstream csv;
  if (!csv_path.empty()) {
    csv.open(csv_path);
    if (!csv) {
      std::cerr << "nao_rt: cannot write " << csv_path << "\n";
      return 2;
    }
  }

  // Everything the loop produces goes into records sized here; the loop itself does no I/O.
  struct TickRecord {
    double t_s;
    nao::JointVector q_cmd, q;
    Eigen::Vector3d p_sim, p_ref;
  };
  std::vector<TickRecord> records(static_cast<std::size_t>(n_ticks));

  for (int tick = 0; tick < n_ticks; ++tick) {
    TickRecord& r = records[static_cast<std::size_t>(tick)];
    r.t_s = (tick + 1) * kTickS;
    r.q = nao::stepSim(sim_model, sim, scriptedCommand(r.t_s));
    r.q_cmd = sim.q_cmd;
    r.p_ref = nao::forwardKinematics(arm, kin, sim.q_cmd);
    r.p_sim = nao::simHandPosition(sim_model, sim);
  }

  std::printf("nao_rt: %s, d_r = %.5f m, %d ticks of %.0f ms\n", urdf_path.c_str(), nao::robotScale(arm), n_ticks,
              kTickS * 1e3);
  std::printf("%7s  %-26s  %-26s  %9s\n", "t [s]", "hand (sim) [m]", "hand (commanded) [m]", "err [mm]");
  double sum_sq = 0.0, worst_mm = 0.0;
  for (int tick = 0; tick < n_ticks; ++tick) {
    const TickRecord& r = records[static_cast<std::size_t>(tick)];
    const double err_mm = (r.p_sim - r.p_ref).norm() * 1e3;
    sum_sq += err_mm * err_mm;
    worst_mm = std::max(worst_mm, err_mm);
    if (tick % 10 == 9 || tick == n_ticks - 1)
      std::printf("%7.1f  (%+.4f, %+.4f, %+.4f)  (%+.4f, %+.4f, %+.4f)  %9.2f\n", r.t_s, r.p_sim.x(), r.p_sim.y(),
                  r.p_sim.z(), r.p_ref.x(), r.p_ref.y(), r.p_ref.z(), err_mm);
  }
  std::printf("hand tracking error (sim vs commanded pose): rms %.2f mm, max %.2f mm over %d ticks\n",
              std::sqrt(sum_sq / n_ticks), worst_mm, n_ticks);

  if (csv.is_open()) {
    csv.precision(9);
    csv << "tick,t_s";
    for (const char* n : {"q_cmd", "q"})
      for (int j = 0; j < nao::kNumJoints; ++j) csv << ',' << n << '_' << j;
    csv << ",ee_x,ee_y,ee_z,ee_ref_x,ee_ref_y,ee_ref_z\n";
    for (int tick = 0; tick < n_ticks; ++tick) {
      const TickRecord& r = records[static_cast<std::size_t>(tick)];
      csv << tick << ',' << r.t_s;
      for (int j = 0; j < nao::kNumJoints; ++j) csv << ',' << r.q_cmd[j];
      for (int j = 0; j < nao::kNumJoints; ++j) csv << ',' << r.q[j];
      csv << ',' << r.p_sim.x() << ',' << r.p_sim.y() << ',' << r.p_sim.z() << ',' << r.p_ref.x() << ','
          << r.p_ref.y() << ',' << r.p_ref.z() << '\n';
    }
    if (!csv) {
      std::cerr << "nao_rt: error while writing " << csv_path << "\n";
      return 1;
    }
    std::printf("per-tick log: %s\n", csv_path.c_str());
  }
  return 0;
}
