// Triangulation accuracy on 4-camera stress recordings (docs/synth.md "Stress recordings"):
// what confidence weighting, a zero-lag low-pass (offline), a causal low-pass (live) and the
// bone-length rule do to the right arm against the synthesiser's truth. Not a timing benchmark:
// nao_triangulation_accuracy prints one table (bench/results/triangulation_accuracy.txt).
//
// Scenes: every movement x demonstrations 0..N-1 (seed 4242), renderStressScene defaults (60 fps,
// a second person crossing, arm swaps in cam1, wrong confident keypoints in cam2, 8 % dropouts,
// 1.5 px pixel noise, confidences 0.6-0.9 per point unrelated to the error). Three regimes:
//   stress    as rendered;
//   synth     not a stress recording: the synthesiser's own two-camera, 30 fps recording (its
//             1-2.5 px noise and dropouts, one person), read back from its files;
//   detector  every detection's confidence redrawn uniformly in [0.2, 0.95] and its pixel moved
//             by an extra N(0, (12 px * (1 - c))^2) per axis: a detector whose confidence says
//             how far off it is (our model of OpenPose, where low-confidence keypoints are the
//             noisy ones), seeded per scene.
// Metrics on the right arm, per frame where the estimate has the arm (and torso) valid:
//   elbow  |elbow flexion (human_kinematics q3) - truth's|, median and 95th percentile, deg;
//   band   share of frames whose forearm |wrist - elbow| lies outside 0.20-0.32 m (adult band);
//   kept   share of frames with shoulder, elbow and wrist valid.
#include "nao/human_kinematics.hpp"
#include "nao/live_skeleton.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/synth_stress.hpp"
#include "nao/tools/triangulate.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace {

using namespace nao;
using namespace nao::tools;
namespace fs = std::filesystem;

constexpr double kDeg = 180.0 / 3.14159265358979323846;

struct Metrics {
  std::vector<double> elbow_deg;
  int n_frames = 0, n_kept = 0, n_forearm = 0, n_out_of_band = 0;
};

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(static_cast<double>(v.size()) - 1.0, q * static_cast<double>(v.size())))];
}

void score(const Skeleton& est, const Skeleton& truth, Metrics& m) {
  HumanArmData est_arm, truth_arm;
  const HumanKinematicsConfig config;
  for (std::size_t k = 0; k < est.size() && k < truth.size(); ++k) {
    const SkeletonFrame& f = est[k];
    ++m.n_frames;
    const bool arm = f.ok[kRShoulder] && f.ok[kRElbow] && f.ok[kRWrist];
    m.n_kept += arm ? 1 : 0;
    if (f.ok[kRElbow] && f.ok[kRWrist]) {
      const double forearm = (f.p_W[kRWrist] - f.p_W[kRElbow]).norm();
      ++m.n_forearm;
      m.n_out_of_band += (forearm < 0.20 || forearm > 0.32) ? 1 : 0;
    }
    humanArmKinematics(config, truth_arm, truth[k]);
    humanArmKinematics(config, est_arm, f);
    if (est_arm.valid && truth_arm.valid)
      m.elbow_deg.push_back(std::abs(est_arm.q[kHumanElbowRoll] - truth_arm.q[kHumanElbowRoll]) * kDeg);
  }
}

// Confidence weights c^power (0: all 1, unweighted; 1: as detected).
void confidencePower(StressScene& scene, double power) {
  for (CameraKeypoints& cam : scene.keypoints)
    for (KeypointFrame& frame : cam.frames)
      for (Person2d& p : frame.people)
        for (double& c : p.confidence)
          if (c > 0.0) c = std::pow(c, power);
}

// The live source's per-frame path on the scene's frames, in order, in process.
Skeleton live(const StressScene& scene, const LiveSkeletonParams& params) {
  TriangulationState triangulation;
  LiveSkeletonState state;
  resetLiveSkeleton(params, scene.fps, state);
  Skeleton out(scene.truth.size());
  const TriangulationParams core;
  for (std::size_t k = 0; k < scene.truth.size(); ++k) {
    std::vector<const std::vector<Person2d>*> people;
    for (const CameraKeypoints& cam : scene.keypoints) people.push_back(&cam.frames[k].people);
    const FrameTriangulation done =
        triangulateFrame(scene.cameras, people, static_cast<double>(k) / scene.fps, core, triangulation, out[k]);
    const FrameObservations observations{&scene.cameras, &people, &done.subject.person};
    advanceLiveSkeleton(params, state, out[k], done.subject.found ? &observations : nullptr);
  }
  return out;
}

// The synthesiser's own two-camera recording (30 fps, its noise and dropouts), through its files.
StressScene twoCameraRecording(const SynthDemo& demo, const fs::path& scratch) {
  writeDemo(demo, scratch.string());
  StressScene s;
  s.fps = demo.fps;
  s.truth = demo.truth;
  s.cameras = demo.cameras;
  for (const std::string& dir : demoCameraDirs((scratch / demo.name).string()))
    s.keypoints.push_back(readOpenPoseFolder(dir, PoseFormat::kBody25));
  return s;
}

struct Config {
  std::string name;
  std::function<Skeleton(const StressScene&)> run;
  double confidence_power = 1.0;
};

}  // namespace

int main(int argc, char** argv) {
  const int n_demos = argc > 1 ? std::atoi(argv[1]) : 2;
  std::vector<Config> configs;
  const auto offline = [](double sigma_s, double bone_fit) {
    return [sigma_s, bone_fit](const StressScene& s) {
      TriangulateOptions opt;
      opt.fps = s.fps;
      opt.rate_hz = s.fps;
      opt.zero_lag_sigma_s = sigma_s;
      opt.bone_fit_px_per_m = bone_fit;
      return triangulateCapture(s.cameras, s.keypoints, opt);
    };
  };
  const auto online = [](double min_cutoff_hz, double beta, double bone_fit) {
    return [min_cutoff_hz, beta, bone_fit](const StressScene& s) {
      LiveSkeletonParams p;
      p.low_pass.min_cutoff_hz = min_cutoff_hz;
      p.low_pass.beta_s_per_m = beta;
      p.bone_fit_px_per_m = bone_fit;
      return live(s, p);
    };
  };
  configs.push_back({"offline, plain (triangulate before)", offline(0.0, 0.0)});
  configs.push_back({"offline, plain, confidences set to 1", offline(0.0, 0.0), 0.0});
  configs.push_back({"offline, bone fit 300 px/m", offline(0.0, 300.0)});
  configs.push_back({"offline, zero-lag 0.05 s", offline(0.05, 0.0)});
  configs.push_back({"offline, zero-lag 0.05 s + fit (default)", offline(0.05, 300.0)});
  configs.push_back({"offline, zero-lag 0.08 s + fit", offline(0.08, 300.0)});
  configs.push_back({"live, plain", online(0.0, 0.0, 0.0)});
  configs.push_back({"live, bone fit 300 px/m", online(0.0, 0.0, 300.0)});
  configs.push_back({"live, One Euro 4 Hz b 2", online(4.0, 2.0, 0.0)});
  configs.push_back({"live, One Euro 4 Hz b 2 + fit (default)", online(4.0, 2.0, 300.0)});
  configs.push_back({"live, One Euro 2 Hz b 0 + fit", online(2.0, 0.0, 300.0)});

  std::vector<StressScene> scenes[3];
  const fs::path scratch = fs::temp_directory_path() / "nao_triangulation_accuracy";
  for (int m = 0; m < 3; ++m)
    for (int d = 0; d < n_demos; ++d) {
      const SynthDemo demo = generateDemo(static_cast<Movement>(m), d, 4242, false);
      scenes[2].push_back(twoCameraRecording(demo, scratch));
      StressOptions so;
      so.seed = 7 + static_cast<std::uint64_t>(3 * d + m);
      StressScene s = renderStressScene(demo, so);
      scenes[0].push_back(s);
      addDetectorNoise(s, 1000 + static_cast<std::uint64_t>(3 * d + m));
      scenes[1].push_back(std::move(s));
    }
  fs::remove_all(scratch);
  const char* regimes[3] = {"stress", "detector", "synth"};
  std::printf("%-40s %-9s %10s %10s %9s %7s\n", "configuration", "noise", "elbow p50", "elbow p95", "band out", "kept");
  for (int r = 0; r < 3; ++r)
    for (const Config& c : configs) {
      Metrics m;
      for (const StressScene& scene : scenes[r]) {
        if (c.confidence_power != 1.0) {
          StressScene weighted = scene;
          confidencePower(weighted, c.confidence_power);
          score(c.run(weighted), scene.truth, m);
        } else {
          score(c.run(scene), scene.truth, m);
        }
      }
      std::printf("%-40s %-9s %8.2f d %8.2f d %8.2f %% %6.2f %%\n", c.name.c_str(), regimes[r], quantile(m.elbow_deg, 0.5),
                  quantile(m.elbow_deg, 0.95), 100.0 * m.n_out_of_band / std::max(1, m.n_forearm),
                  100.0 * m.n_kept / std::max(1, m.n_frames));
      std::fflush(stdout);
    }
  return 0;
}
