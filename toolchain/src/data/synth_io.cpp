// Synthetic demonstrations on disk: OpenPose JSON per frame per camera, calibration.json,
// truth.csv and meta.json (docs/formats.md). Fixed precision everywhere, so a seed gives
// byte-identical files.
#include "nao/tools/command.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/synth.hpp"
#include "nao/tools/triangulate.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <ostream>
#include <sstream>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

void appendf(std::string& out, const char* fmt, double a, double b, double c) {
  char buf[96];
  const int n = std::snprintf(buf, sizeof(buf), fmt, a, b, c);
  out.append(buf, static_cast<std::size_t>(n));
}

// One keypoint triple; undetected points are written as the literal 0,0,0.
void appendPoint(std::string& out, const Eigen::Vector3d& p, bool fine) {
  if (p.z() <= 0.0) {
    out += "0,0,0";
    return;
  }
  appendf(out, fine ? "%.7f,%.7f,%.7f" : "%.3f,%.3f,%.3f", p.x(), p.y(), p.z());
}

std::string openPoseJson(const OpenPoseFrame& f, bool fine) {
  std::string s;
  s.reserve(2048);
  s += "{\"version\":1.3,\"people\":[{\"person_id\":[-1],\"pose_keypoints_2d\":[";
  for (int i = 0; i < kNumBody25; ++i) {
    if (i) s += ',';
    appendPoint(s, f.pose[i], fine);
  }
  s += "],\"face_keypoints_2d\":[],\"hand_left_keypoints_2d\":[],\"hand_right_keypoints_2d\":[";
  for (std::size_t i = 0; i < f.hand_right.size(); ++i) {
    if (i) s += ',';
    appendPoint(s, f.hand_right[i], fine);
  }
  s += "],\"pose_keypoints_3d\":[],\"face_keypoints_3d\":[],\"hand_left_keypoints_3d\":[],"
       "\"hand_right_keypoints_3d\":[]}]}\n";
  return s;
}

void writeText(const fs::path& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw UserError("cannot write " + path.string());
  const std::size_t n = std::fwrite(text.data(), 1, text.size(), f);
  const bool ok = std::fclose(f) == 0 && n == text.size();
  if (!ok) throw UserError("error while writing " + path.string());
}

nlohmann::ordered_json vec(const Eigen::Ref<const Eigen::VectorXd>& v) {
  nlohmann::ordered_json a = nlohmann::ordered_json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) a.push_back(v[i]);
  return a;
}

std::string calibrationJson(const CameraSet& cams) {
  nlohmann::ordered_json cameras = nlohmann::ordered_json::array();
  for (const Camera& c : cams) {
    nlohmann::ordered_json j;
    j["name"] = c.name;
    j["size"] = {c.width, c.height};
    nlohmann::ordered_json K = nlohmann::ordered_json::array();
    for (int r = 0; r < 3; ++r) K.push_back(vec(c.K.row(r).transpose()));
    j["matrix"] = K;
    j["distortions"] = vec(c.dist);
    const Eigen::AngleAxisd aa(c.R_CW);
    j["rotation"] = vec(aa.angle() * aa.axis());
    j["translation"] = vec(c.p_CW);
    cameras.push_back(j);
  }
  nlohmann::ordered_json root;
  root["cameras"] = cameras;
  return root.dump(2) + "\n";
}

std::string deg(const HumanJointVector& q) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << '[';
  for (int j = 0; j < kNumHumanJoints; ++j) s << (j ? ", " : "") << q[j] * 180.0 / 3.14159265358979323846;
  s << ']';
  return s.str();
}

std::string metaJson(const SynthDemo& d) {
  nlohmann::ordered_json j;
  j["generator"] = "nao_toolchain synth";
  j["seed"] = d.seed;
  j["demo_seed"] = d.demo_seed;
  j["movement"] = kMovementNames[static_cast<int>(d.movement)];
  j["index"] = d.index;
  j["noise_free"] = d.noise_free;
  j["fps"] = d.fps;
  j["n_frames"] = d.truth.size();
  j["duration_s"] = d.truth.empty() ? 0.0 : d.truth.back().t_s;
  j["joint_names"] = std::vector<std::string>(std::begin(kHumanJointNames), std::end(kHumanJointNames));
  const Anthropometrics& b = d.body;
  nlohmann::ordered_json body;
  body["sex"] = b.female ? "female" : "male";
  body["stature_m"] = b.stature_m;
  body["upper_arm_m"] = b.upper_arm_m;
  body["forearm_m"] = b.forearm_m;
  body["hand_length_m"] = b.hand_length_m;
  body["hand_segment_m"] = b.hand_segment_m;
  body["scale_d_h_m"] = b.scale_m();
  body["shoulder_width_m"] = b.shoulder_width_m;
  body["hip_width_m"] = b.hip_width_m;
  body["trunk_m"] = b.trunk_m;
  body["leg_m"] = b.leg_m;
  nlohmann::ordered_json hand = nlohmann::ordered_json::object();
  for (int h = 0; h < 4; ++h) hand[std::to_string(kHandKeypointIds[h])] = vec(b.p_KHand[h]);
  body["hand_points_in_hand_frame_m"] = hand;
  j["anthropometrics"] = body;
  const MotionParams& m = d.motion;
  nlohmann::ordered_json motion;
  motion["t_idle_start_s"] = m.t_idle_start_s;
  motion["t_raise_s"] = m.t_raise_s;
  motion["circle_period_s"] = m.circle_period_s;
  motion["n_loops"] = m.n_loops;
  motion["t_lower_s"] = m.t_lower_s;
  motion["t_idle_end_s"] = m.t_idle_end_s;
  motion["direction"] = m.direction;
  motion["phase0_rad"] = m.phase0_rad;
  motion["radius_rad"] = m.radius_rad;
  motion["radius_m"] = m.radius_m;
  motion["q_rest_deg"] = nlohmann::ordered_json::parse(deg(m.q_rest));
  motion["q_centre_deg"] = nlohmann::ordered_json::parse(deg(m.q_centre));
  motion["drift_amp_rad"] = vec(m.drift_amp);
  motion["tremor_amp_rad"] = d.noise_free ? vec(HumanJointVector::Zero()) : vec(m.tremor_amp);
  motion["torso_sway_amp_m"] = vec(m.sway_amp_m);
  motion["torso_yaw_sway_rad"] = m.yaw_sway_rad;
  motion["torso_lean_rad"] = m.lean_rad;
  j["motion"] = motion;
  nlohmann::ordered_json noise;
  noise["pixel_sigma_px"] = d.noise_free ? 0.0 : d.noise.pixel_sigma_px;
  noise["hand_pixel_sigma_px"] = d.noise_free ? 0.0 : 1.5 * d.noise.pixel_sigma_px;
  noise["dropout_prob"] = d.noise_free ? 0.0 : d.noise.dropout_prob;
  noise["hand_dropout_prob"] = d.noise_free ? 0.0 : 3.0 * d.noise.dropout_prob;
  noise["hand_missed_prob"] = d.noise_free ? 0.0 : 0.03;
  j["noise"] = noise;
  return j.dump(2) + "\n";
}

std::string truthCsv(const SynthDemo& d) {
  std::ostringstream out;
  out << "frame," << skeletonCsvHeader();
  for (const char* name : kHumanJointNames) out << ',' << name;
  out << ",phase\n";
  out << std::fixed << std::setprecision(10);
  for (std::size_t k = 0; k < d.truth.size(); ++k) {
    out << k << ',';
    writeSkeletonColumns(out, d.truth[k]);
    for (int j = 0; j < kNumHumanJoints; ++j) out << ',' << d.q[k][j];
    out << ',' << d.phase[k] << '\n';
  }
  return out.str();
}

// Removes this demonstration's own frame files from an earlier run (a shorter demo must not
// leave stale frames behind); nothing else in the folder is touched.
void removeOldFrames(const fs::path& cam_dir, const std::string& demo_name) {
  if (!fs::exists(cam_dir)) return;
  const std::string prefix = demo_name + "_", suffix = "_keypoints.json";
  for (const auto& entry : fs::directory_iterator(cam_dir)) {
    const std::string f = entry.path().filename().string();
    if (f.size() == prefix.size() + 12 + suffix.size() && f.compare(0, prefix.size(), prefix) == 0 &&
        f.compare(f.size() - suffix.size(), suffix.size(), suffix) == 0)
      fs::remove(entry.path());
  }
}

}  // namespace

void writeDemo(const SynthDemo& demo, const std::string& out_dir) {
  const fs::path dir = fs::path(out_dir) / demo.name;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw UserError("cannot create " + dir.string() + ": " + ec.message());
  for (std::size_t c = 0; c < demo.cameras.size(); ++c) {
    const fs::path cam_dir = dir / ("cam" + std::to_string(c));
    fs::create_directories(cam_dir, ec);
    if (ec) throw UserError("cannot create " + cam_dir.string() + ": " + ec.message());
    removeOldFrames(cam_dir, demo.name);
    const std::vector<OpenPoseFrame> frames = renderCamera(demo, static_cast<int>(c));
    char file[96];
    for (std::size_t k = 0; k < frames.size(); ++k) {
      std::snprintf(file, sizeof(file), "%s_%012zu_keypoints.json", demo.name.c_str(), k);
      writeText(cam_dir / file, openPoseJson(frames[k], demo.noise_free));
    }
  }
  writeText(dir / "calibration.json", calibrationJson(demo.cameras));
  writeText(dir / "truth.csv", truthCsv(demo));
  // The truth as nao_rt reads a recorded human (a 10 Hz skeleton CSV, --reference file:): the
  // noise-free skeleton a perfect detector would have given, for comparison with the cameras'.
  writeSkeletonCsv((dir / "truth_skeleton.csv").string(), resampleSkeleton(demo.truth, 10.0, demo.fps));
  writeText(dir / "meta.json", metaJson(demo));
}

int synthesise(const SynthOptions& options, std::ostream& progress) {
  if (options.out_dir.empty()) throw UserError("--out DIR is required");
  if (options.per_movement < 1 || options.per_movement > 1000)
    throw UserError("--per-movement must be between 1 and 1000 (three-digit index), got " +
                    std::to_string(options.per_movement));
  if (options.movements.empty()) throw UserError("no movement selected");
  std::error_code ec;
  fs::create_directories(options.out_dir, ec);
  if (ec) throw UserError("cannot create output directory " + options.out_dir + ": " + ec.message());

  const int n_total = options.per_movement * static_cast<int>(options.movements.size());
  int n_done = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (Movement m : options.movements) {
    for (int i = 0; i < options.per_movement; ++i) {
      const SynthDemo demo = generateDemo(m, i, options.seed, options.noise_free);
      writeDemo(demo, options.out_dir);
      ++n_done;
      char line[200];
      std::snprintf(line, sizeof(line), "[%d/%d] %s: %zu frames (%.1f s), stature %.2f m, d_h %.3f m, radius %.3f m\n",
                    n_done, n_total, demo.name.c_str(), demo.truth.size(), demo.truth.back().t_s, demo.body.stature_m,
                    demo.body.scale_m(), demo.motion.radius_m);
      progress << line << std::flush;
    }
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  char line[160];
  std::snprintf(line, sizeof(line), "wrote %d demonstrations to %s in %.1f s\n", n_done, options.out_dir.c_str(), seconds);
  progress << line;
  return n_done;
}

}  // namespace nao::tools
