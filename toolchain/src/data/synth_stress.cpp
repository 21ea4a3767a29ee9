#include "nao/tools/synth_stress.hpp"

#include "nao/tools/command.hpp"
#include "synth_camera.hpp"
#include "synth_random.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <utility>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr std::array<int, 3> kRightArm = {kRShoulder, kRElbow, kRWrist};
constexpr std::array<int, 3> kLeftArm = {kLShoulder, kLElbow, kLWrist};

// Ring of cameras around the subject's front, aimed at its chest, like the default rig's.
CameraSet stressCameras(const SynthDemo& demo, int n, SynthRandom& rng) {
  CameraSet cams;
  for (int i = 0; i < n; ++i) {
    Camera c = sampleLabIntrinsics(i, rng);
    const double azimuth = (-65.0 + 130.0 * i / (n - 1) + rng.uniform(-4.0, 4.0)) * kDeg;
    const double distance = rng.uniform(3.0, 3.5);
    const Eigen::Vector3d centre_W(distance * std::cos(azimuth), distance * std::sin(azimuth), rng.uniform(1.2, 1.7));
    const Eigen::Vector3d target_W(0.0, -0.15, 0.72 * demo.body.stature_m);
    const Eigen::Vector3d z_C = (target_W - centre_W).normalized();
    const Eigen::Vector3d x_C = z_C.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d y_C = z_C.cross(x_C);
    Eigen::Matrix3d R_WC;
    R_WC << x_C, y_C, z_C;
    c.R_CW = R_WC.transpose();
    c.p_CW = -(c.R_CW * centre_W);
    cams.push_back(c);
  }
  return cams;
}

// The demonstration's truth at time t (linear between its frames; held after the last).
SkeletonFrame truthAt(const SynthDemo& demo, double t) {
  const double s = t * demo.fps;
  const auto k = std::min(static_cast<std::size_t>(std::floor(s)), demo.truth.size() - 1);
  const std::size_t k1 = std::min(k + 1, demo.truth.size() - 1);
  const double w = std::clamp(s - static_cast<double>(k), 0.0, 1.0);
  SkeletonFrame f = demo.truth[k];
  for (int i = 0; i < kNumSkeletonPoints; ++i) f.p_W[i] = (1.0 - w) * demo.truth[k].p_W[i] + w * demo.truth[k1].p_W[i];
  f.t_s = t;
  return f;
}

// Body capsules (segment, radius m) that hide what lies behind them in an image.
struct Capsule {
  int a, b;
  double radius_m;
};
constexpr std::array<Capsule, 10> kCapsules = {{{kNeck, kMidHip, 0.20},
                                                {kNose, kNeck, 0.11},
                                                {kRShoulder, kRElbow, 0.06},
                                                {kRElbow, kRWrist, 0.05},
                                                {kLShoulder, kLElbow, 0.06},
                                                {kLElbow, kLWrist, 0.05},
                                                {kRHip, kRKnee, 0.09},
                                                {kRKnee, kRAnkle, 0.07},
                                                {kLHip, kLKnee, 0.09},
                                                {kLKnee, kLAnkle, 0.07}}};

// True when point p_W of one person is behind `other`'s body in camera cam's image.
bool hiddenBy(const Camera& cam, const Eigen::Vector3d& p_W, const SkeletonFrame& other) {
  const double depth = toCamera(cam, p_W).z();
  for (const Capsule& c : kCapsules) {
    const Eigen::Vector3d a_C = toCamera(cam, other.p_W[c.a]), b_C = toCamera(cam, other.p_W[c.b]);
    if (a_C.z() < 0.1 || b_C.z() < 0.1 || std::max(a_C.z(), b_C.z()) + 0.1 > depth) continue;
    const Eigen::Vector2d a = project(cam, other.p_W[c.a]), b = project(cam, other.p_W[c.b]);
    const Eigen::Vector2d x = project(cam, p_W);
    const Eigen::Vector2d ab = b - a;
    const double s = ab.squaredNorm() > 0.0 ? std::clamp((x - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
    const double radius_px = c.radius_m * cam.K(0, 0) / (0.5 * (a_C.z() + b_C.z()));
    if ((x - (a + s * ab)).norm() < radius_px) return true;
  }
  return false;
}

bool inImage(const Camera& cam, const Eigen::Vector2d& px) {
  return px.x() >= 0.0 && px.y() >= 0.0 && px.x() < cam.width && px.y() < cam.height;
}

void writeText(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw UserError("cannot write " + path.string());
}

}  // namespace

StressScene renderStressScene(const SynthDemo& demo, const StressOptions& opt) {
  if (opt.n_cameras < 2 || opt.n_cameras > 16) throw UserError("a stress recording needs 2 to 16 cameras");
  if (opt.swap_camera >= opt.n_cameras || opt.wrong_camera >= opt.n_cameras)
    throw UserError("the swap and wrong-keypoint cameras must be among the cameras");
  if (!(opt.fps > 0.0)) throw UserError("the stress recording's fps must be positive");
  if (demo.truth.empty()) throw UserError("the demonstration has no frames");
  SynthRandom rng(splitMix64(demo.demo_seed ^ splitMix64(0x57e55ULL + opt.seed)));
  StressScene s;
  s.name = demo.name + "_stress";
  s.fps = opt.fps;
  s.cameras = stressCameras(demo, opt.n_cameras, rng);
  const double duration_s = static_cast<double>(demo.truth.size() - 1) / demo.fps;
  int n = static_cast<int>(std::floor(duration_s * opt.fps + 1e-9)) + 1;
  if (opt.n_frames > 0) n = std::min(n, opt.n_frames);
  const auto n_cam = static_cast<std::size_t>(opt.n_cameras);

  // Per-point confidences, per-block swap flags, the bystander's walk.
  std::array<double, kNumSkeletonPoints> conf{};
  for (double& c : conf) c = rng.uniform(0.6, 0.9);
  std::vector<bool> swap_block(static_cast<std::size_t>(std::ceil(n / opt.fps / 0.5)) + 1);
  for (std::size_t b = 0; b < swap_block.size(); ++b) swap_block[b] = rng.uniform() < opt.swap_fraction;
  // It enters from the side (y = +3 m, beside the outer camera) and walks across and back.
  const double walk_period_s = rng.uniform(5.0, 7.0), walk_phase = 0.0;
  const double walk_x = rng.uniform(0.9, 1.3), pose_shift_s = 0.5 * duration_s;

  s.keypoints.resize(n_cam);
  for (std::size_t c = 0; c < n_cam; ++c) s.keypoints[c].dir = s.cameras[c].name;
  for (int k = 0; k < n; ++k) {
    const double t = k / opt.fps;
    const SkeletonFrame subject = truthAt(demo, t);
    s.truth.push_back(subject);
    SkeletonFrame other;
    if (opt.bystander) {
      // A time-shifted copy of the subject's own motion (the hardest case: same build, same
      // kind of gestures), walking along y in front of the subject.
      other = truthAt(demo, std::fmod(t + pose_shift_s, duration_s));
      const Eigen::Vector3d offset(walk_x, 3.0 * std::cos(2.0 * kPi * t / walk_period_s + walk_phase), 0.0);
      for (auto& p : other.p_W) p += offset;
      other.t_s = t;
      s.bystander.push_back(other);
    }
    std::array<std::uint32_t, kNumSkeletonPoints> correct{};
    std::vector<Person2d> subj(n_cam), bys(n_cam);
    std::vector<std::array<bool, kNumSkeletonPoints>> subject_good(n_cam);
    for (std::size_t c = 0; c < n_cam; ++c) {
      const Camera& cam = s.cameras[c];
      auto detect = [&](const Eigen::Vector3d& p_W, const SkeletonFrame* hider, double sigma, double confidence,
                        Person2d& person, int i) {
        // Every random number is drawn whether or not it is used (one fate must not shift others).
        const double nx = rng.normal(), ny = rng.normal(), nc = rng.normal();
        if (toCamera(cam, p_W).z() < 0.1) return false;
        const Eigen::Vector2d px = project(cam, p_W) + sigma * Eigen::Vector2d(nx, ny);
        if (!inImage(cam, px)) return false;
        if (hider != nullptr && hiddenBy(cam, p_W, *hider)) {
          if (hider == &other) ++s.n_hidden_points;
          return false;
        }
        person.px[i] = px;
        person.confidence[i] = std::clamp(confidence + 0.05 * nc, 0.05, 0.99);
        return true;
      };
      for (int i = 0; i < kNumSkeletonPoints; ++i) {
        const double sigma = (i >= kNumBody25 ? 1.5 : 1.0) * opt.pixel_sigma_px;
        subject_good[c][i] = detect(subject.p_W[i], opt.bystander ? &other : nullptr, sigma, conf[i], subj[c], i);
        if (opt.bystander && i < kNumBody25) detect(other.p_W[i], &subject, sigma, conf[i], bys[c], i);
      }
    }
    for (std::size_t c = 0; c < n_cam; ++c)
      for (int i = 0; i < kNumSkeletonPoints; ++i)
        if (subject_good[c][i]) correct[i] |= std::uint32_t{1} << c;
    // A fault in camera c may only take right-arm views that others can spare (each arm point
    // keeps >= 2 correct views): faults are skipped where occlusion already took too many.
    const auto spare = [&](std::size_t c, int i) {
      return ((correct[i] >> c) & 1u) == 0u || __builtin_popcount(correct[i]) > 2;
    };
    // Left/right arm swap in bursts of 0.5 s.
    if (opt.swap_camera >= 0 && swap_block[static_cast<std::size_t>(t / 0.5)]) {
      const auto c = static_cast<std::size_t>(opt.swap_camera);
      if (std::all_of(kRightArm.begin(), kRightArm.end(), [&](int i) { return spare(c, i); })) {
        ++s.n_swapped_frames;
        for (std::size_t j = 0; j < kRightArm.size(); ++j) {
          std::swap(subj[c].px[kRightArm[j]], subj[c].px[kLeftArm[j]]);
          std::swap(subj[c].confidence[kRightArm[j]], subj[c].confidence[kLeftArm[j]]);
          for (int i : {kRightArm[j], kLeftArm[j]}) correct[i] &= ~(std::uint32_t{1} << c);
        }
      }
    }
    // A wrong but confident arm keypoint.
    const double u_wrong = rng.uniform(), u_which = rng.uniform(), u_dist = rng.uniform(), u_dir = rng.uniform();
    if (opt.wrong_camera >= 0 && u_wrong < opt.wrong_prob) {
      const auto c = static_cast<std::size_t>(opt.wrong_camera);
      const Camera& cam = s.cameras[c];
      const int i = kRightArm[std::min<std::size_t>(2, static_cast<std::size_t>(3.0 * u_which))];
      const Eigen::Vector2d px = project(cam, subject.p_W[i]) +
                                 (40.0 + 110.0 * u_dist) * Eigen::Vector2d(std::cos(2 * kPi * u_dir), std::sin(2 * kPi * u_dir));
      if (toCamera(cam, subject.p_W[i]).z() >= 0.1 && inImage(cam, px) && spare(c, i)) {
        ++s.n_wrong_keypoints;
        subj[c].px[i] = px;
        subj[c].confidence[i] = 0.95;
        correct[i] &= ~(std::uint32_t{1} << c);
      }
    }
    // Dropouts, camera by camera; an arm point keeps at least two correct views.
    for (std::size_t c = 0; c < n_cam; ++c)
      for (int i = 0; i < kNumSkeletonPoints; ++i) {
        const double u = rng.uniform(), u_bys = rng.uniform();
        if (opt.bystander && i < kNumBody25 && u_bys < opt.dropout_prob) bys[c].confidence[i] = 0.0;
        if (u >= opt.dropout_prob || subj[c].confidence[i] == 0.0) continue;
        const bool arm = std::find(kRightArm.begin(), kRightArm.end(), i) != kRightArm.end();
        const bool is_correct = (correct[i] >> c) & 1u;
        if (arm && is_correct && __builtin_popcount(correct[i]) <= 2) continue;
        subj[c].confidence[i] = 0.0;
        subj[c].px[i].setZero();
        correct[i] &= ~(std::uint32_t{1} << c);
      }
    s.correct_views.push_back(correct);
    // People of each frame file, in random order.
    std::vector<int> subject_at(n_cam, -1), bystander_at(n_cam, -1);
    for (std::size_t c = 0; c < n_cam; ++c) {
      KeypointFrame f;
      f.index = k;
      const auto seen = [](const Person2d& p, int min_points) {
        return std::count_if(p.confidence.begin(), p.confidence.end(), [](double v) { return v > 0.0; }) >= min_points;
      };
      const bool bystander_first = rng.uniform() < 0.5;
      const bool has_subject = seen(subj[c], 1), has_bystander = opt.bystander && seen(bys[c], 5);
      for (int slot = 0; slot < 2; ++slot) {
        const bool subject_slot = (slot == 0) != bystander_first;
        if (subject_slot && has_subject) subject_at[c] = static_cast<int>(f.people.size()), f.people.push_back(subj[c]);
        if (!subject_slot && has_bystander) bystander_at[c] = static_cast<int>(f.people.size()), f.people.push_back(bys[c]);
      }
      s.keypoints[c].frames.push_back(std::move(f));
    }
    s.subject_index.push_back(subject_at);
    s.bystander_index.push_back(bystander_at);
  }
  return s;
}

void writeStressScene(const StressScene& scene, const std::string& out_dir) {
  const fs::path dir = fs::path(out_dir) / scene.name;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw UserError("cannot create " + dir.string() + ": " + ec.message());
  char file[160], num[64];
  for (std::size_t c = 0; c < scene.cameras.size(); ++c) {
    const fs::path cam_dir = dir / scene.cameras[c].name;
    fs::create_directories(cam_dir, ec);
    if (ec) throw UserError("cannot create " + cam_dir.string() + ": " + ec.message());
    for (const KeypointFrame& f : scene.keypoints[c].frames) {
      std::string json = "{\"version\":1.3,\"people\":[";
      for (std::size_t p = 0; p < f.people.size(); ++p) {
        const Person2d& person = f.people[p];
        auto point = [&](int i, bool first) {
          const bool on = person.confidence[i] > 0.0;
          std::snprintf(num, sizeof(num), "%s%.3f,%.3f,%.3f", first ? "" : ",", on ? person.px[i].x() : 0.0,
                        on ? person.px[i].y() : 0.0, on ? person.confidence[i] : 0.0);
          json += num;
        };
        json += p == 0 ? "{\"person_id\":[-1],\"pose_keypoints_2d\":[" : ",{\"person_id\":[-1],\"pose_keypoints_2d\":[";
        for (int i = 0; i < kNumBody25; ++i) point(i, i == 0);
        json += "],\"hand_right_keypoints_2d\":[";
        for (int h = 0; h < 21; ++h) {
          const auto it = std::find(kHandKeypointIds.begin(), kHandKeypointIds.end(), h);
          if (it == kHandKeypointIds.end()) {
            json += h == 0 ? "0,0,0" : ",0,0,0";
          } else {
            point(kRHand0 + static_cast<int>(it - kHandKeypointIds.begin()), h == 0);
          }
        }
        json += "],\"hand_left_keypoints_2d\":[],\"face_keypoints_2d\":[]}";
      }
      json += "]}\n";
      std::snprintf(file, sizeof(file), "%s_%012lld_keypoints.json", scene.name.c_str(), f.index);
      writeText(cam_dir / file, json);
    }
  }
  nlohmann::ordered_json calib;
  calib["cameras"] = nlohmann::ordered_json::array();
  for (const Camera& cam : scene.cameras) {
    nlohmann::ordered_json j;
    j["name"] = cam.name;
    j["size"] = {cam.width, cam.height};
    j["matrix"] = nlohmann::ordered_json::array();
    j["rotation"] = nlohmann::ordered_json::array();
    for (int r = 0; r < 3; ++r) {
      j["matrix"].push_back({cam.K(r, 0), cam.K(r, 1), cam.K(r, 2)});
      j["rotation"].push_back({cam.R_CW(r, 0), cam.R_CW(r, 1), cam.R_CW(r, 2)});
    }
    j["distortions"] = {cam.dist[0], cam.dist[1], cam.dist[2], cam.dist[3], cam.dist[4]};
    j["translation"] = {cam.p_CW.x(), cam.p_CW.y(), cam.p_CW.z()};
    calib["cameras"].push_back(j);
  }
  writeText(dir / "calibration.json", calib.dump(2) + "\n");
  writeSkeletonCsv((dir / "truth.csv").string(), scene.truth);
}

void addDetectorNoise(StressScene& scene, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> conf(0.2, 0.95);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (CameraKeypoints& cam : scene.keypoints)
    for (KeypointFrame& frame : cam.frames)
      for (Person2d& p : frame.people)
        for (int i = 0; i < kNumSkeletonPoints; ++i) {
          const double c = conf(rng), nx = normal(rng), ny = normal(rng);
          if (!p.detected(i)) continue;
          p.confidence[i] = c;
          p.px[i] += 12.0 * (1.0 - c) * Eigen::Vector2d(nx, ny);
        }
}

}  // namespace nao::tools
