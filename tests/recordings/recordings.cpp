// Test recordings (recordings.hpp): subject, movements, cameras, detections and files.
#include "recordings.hpp"

#include "nao/tools/skeleton_csv.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <ostream>
#include <random>
#include <stdexcept>

namespace nao::recordings {
namespace {

namespace fs = std::filesystem;
using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kFps = 30.0;

std::uint64_t splitMix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Uniform and normal variates from the engine's raw bits: the same numbers with any standard library.
class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double normal() {
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
  }

 private:
  std::mt19937_64 engine_;
};

double minimumJerk(double s) {
  s = std::clamp(s, 0.0, 1.0);
  return s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
}

Matrix3d rotation(const Vector3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

// Direction on the great circle from a to b (not antipodal), s in [0, 1].
Vector3d slerpDirection(const Vector3d& a, const Vector3d& b, double s) {
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(a, b);
  return (Eigen::Quaterniond::Identity().slerp(s, q) * a).normalized();
}

// Unit vector perpendicular to `axis`, as near `wish` as possible.
Vector3d perpendicular(const Vector3d& axis, const Vector3d& wish) { return (wish - axis * axis.dot(wish)).normalized(); }

// The right arm in the torso frame T (x forward, y left, z up): directions of the upper arm
// and the forearm, the palm's normal (made perpendicular to the hand axis), and the wrist's
// flexion (towards the palm) and ulnar deviation about the hand's own axes.
struct ArmPose {
  Vector3d u = -Vector3d::UnitZ();
  Vector3d f = -Vector3d::UnitZ();
  Vector3d palm = Vector3d::UnitY();
  double wrist_flex = 0.0, wrist_dev = 0.0;
};

ArmPose blend(const ArmPose& a, const ArmPose& b, double s) {
  ArmPose p;
  p.u = slerpDirection(a.u, b.u, s);
  p.f = slerpDirection(a.f, b.f, s);
  p.palm = slerpDirection(a.palm, b.palm, s);
  p.wrist_flex = a.wrist_flex + s * (b.wrist_flex - a.wrist_flex);
  p.wrist_dev = a.wrist_dev + s * (b.wrist_dev - a.wrist_dev);
  return p;
}

ArmPose rotated(const Matrix3d& R, ArmPose p) {
  p.u = R * p.u;
  p.f = R * p.f;
  p.palm = R * p.palm;
  return p;
}

// A movement as a function of time: the arm pose, and the length of the recording.
struct Motion {
  double duration_s = 0.0;
  std::function<ArmPose(double t)> pose;
};

// Upper arm raised by `elevation` from hanging, in the plane turned `plane` forward of the
// frontal plane (0: straight out to the side).
Vector3d elevated(double elevation, double plane) {
  return {std::sin(elevation) * std::sin(plane), -std::sin(elevation) * std::cos(plane), -std::cos(elevation)};
}

// Arm hanging relaxed: the upper arm a little forward and out, the elbow bent forward, the
// palm towards the thigh (twisted a little).
ArmPose sampleRest(Random& rng) {
  ArmPose p;
  p.u = Vector3d(rng.uniform(0.02, 0.12), rng.uniform(-0.10, -0.02), -1.0).normalized();
  const double bend = rng.uniform(8.0, 25.0) * kDeg;
  p.f = std::cos(bend) * p.u + std::sin(bend) * perpendicular(p.u, Vector3d::UnitX());
  const double twist = rng.uniform(-15.0, 15.0) * kDeg;
  p.palm = Vector3d(std::sin(twist), std::cos(twist), 0.0);
  p.wrist_flex = rng.uniform(-5.0, 5.0) * kDeg;
  p.wrist_dev = rng.uniform(0.0, 8.0) * kDeg;
  return p;
}

using Params = std::vector<std::pair<std::string, double>>;

// Total length in [6, 10] s that leaves at least `active_min_s` (<= 10 - fixed_s) beyond `fixed_s`.
double sampleDuration(Random& rng, double fixed_s, double active_min_s) {
  return rng.uniform(std::max(6.0, fixed_s + active_min_s), 10.0);
}

// Wave: upper arm raised 55-75 deg to the side, forearm up, the hand above the shoulder,
// waving by swinging the forearm side to side with the wrist deviating in step.
Motion waveMotion(Random& rng, Params& params) {
  const ArmPose rest0 = sampleRest(rng), rest1 = sampleRest(rng);
  const double elevation = rng.uniform(55.0, 75.0) * kDeg, plane = rng.uniform(0.0, 30.0) * kDeg;
  const double hz = rng.uniform(1.0, 2.0), swing = rng.uniform(15.0, 30.0) * kDeg;
  const double tilt = rng.uniform(-10.0, 10.0) * kDeg, dev = rng.uniform(5.0, 15.0) * kDeg;
  const double lag = rng.uniform(0.0, 0.5), palm_turn = rng.uniform(-20.0, 20.0) * kDeg;
  const double flex = rng.uniform(-15.0, 10.0) * kDeg;
  const double t_idle0 = rng.uniform(0.3, 0.8), t_raise = rng.uniform(0.9, 1.6), t_lower = rng.uniform(0.9, 1.6),
               t_idle1 = rng.uniform(0.3, 0.8);
  const double fixed = t_idle0 + t_raise + t_lower + t_idle1;
  const double duration = sampleDuration(rng, fixed, 2.0);
  const double t_wave = duration - fixed;
  params.insert(params.end(), {{"elevation_deg", elevation / kDeg}, {"plane_deg", plane / kDeg}, {"wave_hz", hz},
                               {"swing_deg", swing / kDeg}, {"tilt_deg", tilt / kDeg}, {"deviation_deg", dev / kDeg},
                               {"wave_s", t_wave}});

  // The waving pose at swing angle `theta` (from vertical, outward positive) and deviation `d`.
  auto waving = [=](double theta, double d, double lift) {
    ArmPose p;
    p.u = elevated(elevation + lift, plane);
    const Vector3d out = Vector3d(p.u.x(), p.u.y(), 0.0).normalized();
    p.f = std::cos(tilt + theta) * Vector3d::UnitZ() + std::sin(tilt + theta) * out;
    p.palm = Vector3d(std::cos(palm_turn), std::sin(palm_turn), 0.0);
    p.wrist_flex = flex;
    p.wrist_dev = d;
    return p;
  };
  const double t0 = t_idle0 + t_raise, t1 = t0 + t_wave;
  Motion m;
  m.duration_s = duration;
  m.pose = [=](double t) {
    if (t < t0) return blend(rest0, waving(0.0, 0.0, 0.0), minimumJerk((t - t_idle0) / t_raise));
    if (t < t1) {
      const double tau = t - t0;
      // The swing fades in and out over 0.4 s, so the arm's velocity stays continuous.
      const double envelope = minimumJerk(tau / 0.4) * minimumJerk((t_wave - tau) / 0.4);
      const double phase = 2.0 * kPi * hz * tau;
      const double theta = envelope * swing * std::sin(phase);
      return waving(theta, envelope * dev * std::sin(phase - lag), 0.12 * theta);
    }
    return blend(waving(0.0, 0.0, 0.0), rest1, minimumJerk((t - t1) / t_lower));
  };
  return m;
}

// Reach: the hand forward to shoulder height, nearly straight arm, a pause, back to rest;
// once or twice.
Motion reachMotion(Random& rng, const Subject& body, Params& params) {
  const ArmPose rest = sampleRest(rng);
  const double azimuth = rng.uniform(-25.0, 5.0) * kDeg, height = rng.uniform(-0.05, 0.05);
  const double bend = rng.uniform(5.0, 20.0) * kDeg, pronation = rng.uniform(0.0, 70.0) * kDeg;
  const double t_out = rng.uniform(0.8, 1.4), t_pause = rng.uniform(0.6, 1.5), t_back = rng.uniform(0.8, 1.4),
               t_gap = rng.uniform(0.5, 1.0);
  const double t_rep = t_out + t_pause + t_back;
  const double t_idle0 = rng.uniform(0.3, 0.8);
  int reps = rng.uniform() < 0.5 ? 1 : 2;
  if (t_idle0 + 0.3 + 2 * t_rep + t_gap > 9.5) reps = 1;
  const double active = reps * t_rep + (reps - 1) * t_gap;
  const double duration = sampleDuration(rng, t_idle0 + 0.3, active);
  params.insert(params.end(), {{"azimuth_deg", azimuth / kDeg}, {"height_m", height}, {"elbow_deg", bend / kDeg},
                               {"pronation_deg", pronation / kDeg}, {"reach_s", t_out}, {"pause_s", t_pause},
                               {"return_s", t_back}, {"repetitions", reps}});

  // The arm nearly straight towards the target: the elbow drops below the shoulder-hand line
  // so that the upper arm and the forearm + half palm meet it at the bend.
  const double reach = body.upper_arm_m + body.forearm_m + 0.5 * body.palm_m;
  const Vector3d d = Vector3d(std::cos(azimuth), std::sin(azimuth), height / reach).normalized();
  const Vector3d up = perpendicular(d, Vector3d::UnitZ());
  const double lower = body.forearm_m + 0.5 * body.palm_m;
  const double a_upper = std::atan2(lower * std::sin(bend), body.upper_arm_m + lower * std::cos(bend));
  ArmPose out;
  out.u = std::cos(a_upper) * d - std::sin(a_upper) * up;
  out.f = std::cos(bend - a_upper) * d + std::sin(bend - a_upper) * up;
  out.palm = std::cos(pronation) * Vector3d::UnitY() - std::sin(pronation) * Vector3d::UnitZ();
  out.wrist_flex = rng.uniform(-10.0, 5.0) * kDeg;
  out.wrist_dev = rng.uniform(0.0, 10.0) * kDeg;
  const double drift = rng.uniform(0.5, 1.5) * kDeg, drift_hz = rng.uniform(0.3, 0.8);

  Motion m;
  m.duration_s = duration;
  m.pose = [=](double t) {
    double tau = t - t_idle0;
    for (int r = 0; r < reps && tau >= 0.0; ++r, tau -= t_rep + t_gap) {
      if (tau < t_out) return blend(rest, out, minimumJerk(tau / t_out));
      if (tau < t_out + t_pause) {
        // Holding still is never perfectly still.
        const double wobble = drift * std::sin(2.0 * kPi * drift_hz * (tau - t_out));
        return rotated(rotation(Vector3d::UnitY(), wobble), out);
      }
      if (tau < t_rep) return blend(out, rest, minimumJerk((tau - t_out - t_pause) / t_back));
    }
    return rest;
  };
  return m;
}

// Lateral raise: the nearly straight arm swung up sideways through the horizontal (80-110 deg
// from hanging) and down again, 2 or 3 times; the palm turns down as the arm rises.
Motion sideRaiseMotion(Random& rng, Params& params) {
  const double top = rng.uniform(80.0, 110.0) * kDeg, bottom = rng.uniform(3.0, 10.0) * kDeg;
  const double plane = rng.uniform(-5.0, 25.0) * kDeg, bend = rng.uniform(5.0, 20.0) * kDeg;
  int reps = rng.uniform() < 0.5 ? 2 : 3;
  const double t_up = rng.uniform(0.9, 1.5), t_hold = rng.uniform(0.2, 0.6), t_down = rng.uniform(0.9, 1.5),
               t_gap = rng.uniform(0.2, 0.6), t_idle0 = rng.uniform(0.3, 0.8);
  const double t_rep = t_up + t_hold + t_down;
  while (reps > 1 && t_idle0 + 0.3 + reps * t_rep + (reps - 1) * t_gap > 9.5) --reps;
  const double duration = sampleDuration(rng, t_idle0 + 0.3, reps * t_rep + (reps - 1) * t_gap);
  params.insert(params.end(), {{"top_deg", top / kDeg}, {"plane_deg", plane / kDeg}, {"elbow_deg", bend / kDeg},
                               {"repetitions", reps}, {"up_s", t_up}, {"down_s", t_down}});

  // The hanging arm (elbow bent forward, palm in) turned about the horizontal axis of the
  // plane of elevation.
  ArmPose hanging;
  hanging.u = -Vector3d::UnitZ();
  hanging.f = -std::cos(bend) * Vector3d::UnitZ() + std::sin(bend) * Vector3d::UnitX();
  hanging.palm = Vector3d::UnitY();
  hanging.wrist_dev = rng.uniform(0.0, 8.0) * kDeg;
  const Vector3d axis(std::cos(plane), std::sin(plane), 0.0);
  auto at = [=](double elevation) { return rotated(rotation(axis, -elevation), hanging); };

  Motion m;
  m.duration_s = duration;
  m.pose = [=](double t) {
    double tau = t - t_idle0;
    for (int r = 0; r < reps && tau >= 0.0; ++r, tau -= t_rep + t_gap) {
      if (tau < t_up) return at(bottom + (top - bottom) * minimumJerk(tau / t_up));
      if (tau < t_up + t_hold) return at(top);
      if (tau < t_rep) return at(top + (bottom - top) * minimumJerk((tau - t_up - t_hold) / t_down));
    }
    return at(bottom);
  };
  return m;
}

Subject sampleSubject(Random& rng) {
  Subject b;
  const bool female = rng.uniform() < 0.5;
  b.stature_m = std::clamp(female ? 1.62 + 0.065 * rng.normal() : 1.76 + 0.07 * rng.normal(), 1.45, 2.0);
  const double H = b.stature_m;
  auto part = [&](double fraction) { return fraction * H * std::clamp(1.0 + 0.03 * rng.normal(), 0.92, 1.08); };
  b.upper_arm_m = part(0.186);
  b.forearm_m = part(0.146);
  b.palm_m = part(0.062);
  b.hand_breadth_m = part(0.05);
  b.shoulder_width_m = part(0.205);
  b.hip_width_m = part(0.16);
  b.trunk_m = part(0.288);
  b.leg_m = part(0.53);
  return b;
}

// Two cameras in front of the subject, one to each side, aimed at the chest.
tools::CameraSet sampleCameras(const Subject& body, Random& rng) {
  tools::CameraSet cams;
  for (int i = 0; i < 2; ++i) {
    tools::Camera c;
    c.name = "cam" + std::to_string(i);
    c.width = 1920;
    c.height = 1080;
    const double f = rng.uniform(1000.0, 1200.0);
    c.K << f, 0.0, 960.0 + rng.uniform(-8.0, 8.0), 0.0, f * (1.0 + rng.uniform(-0.002, 0.002)),
        540.0 + rng.uniform(-8.0, 8.0), 0.0, 0.0, 1.0;
    c.dist << rng.uniform(-0.10, -0.03), rng.uniform(0.0, 0.05), rng.uniform(-3e-4, 3e-4), rng.uniform(-3e-4, 3e-4), 0.0;
    const double azimuth = (i == 0 ? -1.0 : 1.0) * rng.uniform(25.0, 35.0) * kDeg;
    const double distance = rng.uniform(2.8, 3.4);
    const Vector3d centre_W(distance * std::cos(azimuth), distance * std::sin(azimuth), rng.uniform(1.2, 1.6));
    const Vector3d target_W(0.0, -0.15, 0.75 * body.stature_m);
    // Camera axes: z along the optical axis, y down in the image, x to the right.
    const Vector3d z_C = (target_W - centre_W).normalized();
    const Vector3d x_C = z_C.cross(Vector3d::UnitZ()).normalized();
    Matrix3d R_WC;
    R_WC << x_C, z_C.cross(x_C), z_C;
    R_WC = R_WC * rotation(Vector3d::UnitZ(), 0.5 * kDeg * rng.normal());
    // Through the Rodrigues vector the calibration file holds, so the file describes exactly
    // the camera that made the pixels.
    const Eigen::AngleAxisd aa(Matrix3d(R_WC.transpose()));
    c.R_CW = Eigen::AngleAxisd(aa.angle(), aa.axis()).toRotationMatrix();
    c.p_CW = -(c.R_CW * centre_W);
    cams.push_back(c);
  }
  return cams;
}

// Everything but the right arm, in the torso frame (origin at the shoulder midpoint), and the
// legs in the world (the feet stay where they stand).
void fillBody(const Subject& b, const Matrix3d& R_WT, const Vector3d& p_WT, const Vector3d& feet_W,
              const Matrix3d& R_Wfeet, SkeletonFrame& f) {
  const double H = b.stature_m, sw = 0.5 * b.shoulder_width_m, hw = 0.5 * b.hip_width_m;
  auto put = [&](int i, const Vector3d& p_T) {
    f.p_W[i] = R_WT * p_T + p_WT;
    f.ok[i] = true;
  };
  put(kNeck, {-0.012 * H, 0.0, 0.022 * H});
  put(kNose, {0.058 * H, 0.0, 0.09 * H});
  put(kREye, {0.048 * H, -0.019 * H, 0.116 * H});
  put(kLEye, {0.048 * H, 0.019 * H, 0.116 * H});
  put(kREar, {0.0, -0.044 * H, 0.106 * H});
  put(kLEar, {0.0, 0.044 * H, 0.106 * H});
  put(kRShoulder, {0.0, -sw, 0.0});
  put(kLShoulder, {0.0, sw, 0.0});
  const Vector3d p_TLE = Vector3d(0.0, sw, 0.0) + b.upper_arm_m * Vector3d(0.04, 0.05, -1.0).normalized();
  put(kLElbow, p_TLE);
  put(kLWrist, p_TLE + b.forearm_m * Vector3d(0.22, 0.02, -1.0).normalized());
  put(kMidHip, {0.0, 0.0, -b.trunk_m});
  put(kRHip, {0.0, -hw, -b.trunk_m});
  put(kLHip, {0.0, hw, -b.trunk_m});
  const double foot = 0.152 * H, ankle_z = 0.039 * H;
  const int hip[2] = {kRHip, kLHip}, knee[2] = {kRKnee, kLKnee}, ankle[2] = {kRAnkle, kLAnkle};
  const int heel[2] = {kRHeel, kLHeel}, big[2] = {kRBigToe, kLBigToe}, small[2] = {kRSmallToe, kLSmallToe};
  for (int s = 0; s < 2; ++s) {
    const double side = s == 0 ? -1.0 : 1.0;
    const Vector3d p_ankle = feet_W + R_Wfeet * Vector3d(0.0, side * hw, ankle_z);
    auto foot_point = [&](int i, const Vector3d& offset) {
      f.p_W[i] = p_ankle + R_Wfeet * offset;
      f.ok[i] = true;
    };
    f.p_W[ankle[s]] = p_ankle;
    f.ok[ankle[s]] = true;
    f.p_W[knee[s]] = 0.5 * (f.p_W[hip[s]] + p_ankle) + R_Wfeet * Vector3d(0.02, 0.0, 0.0);
    f.ok[knee[s]] = true;
    foot_point(heel[s], {-0.25 * foot, 0.0, -0.8 * ankle_z});
    foot_point(big[s], {0.75 * foot, -side * 0.012, -0.8 * ankle_z});
    foot_point(small[s], {0.64 * foot, side * 0.034, -0.8 * ankle_z});
  }
}

void writeText(const fs::path& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) throw std::runtime_error("cannot write " + path.string());
  const std::size_t n = std::fwrite(text.data(), 1, text.size(), f);
  if (std::fclose(f) != 0 || n != text.size()) throw std::runtime_error("error while writing " + path.string());
}

void appendPoint(std::string& out, const Vector3d& p) {
  if (p.z() <= 0.0) {
    out += "0,0,0";
    return;
  }
  char buf[96];
  const int n = std::snprintf(buf, sizeof(buf), "%.3f,%.3f,%.3f", p.x(), p.y(), p.z());
  out.append(buf, static_cast<std::size_t>(n));
}

std::string openPoseJson(const Detections& d) {
  std::string s;
  s.reserve(2048);
  s += "{\"version\":1.3,\"people\":[{\"person_id\":[-1],\"pose_keypoints_2d\":[";
  for (int i = 0; i < kNumBody25; ++i) {
    if (i > 0) s += ',';
    appendPoint(s, d.pose[i]);
  }
  s += "],\"face_keypoints_2d\":[],\"hand_left_keypoints_2d\":[],\"hand_right_keypoints_2d\":[";
  for (std::size_t i = 0; i < d.hand_right.size(); ++i) {
    if (i > 0) s += ',';
    appendPoint(s, d.hand_right[i]);
  }
  s += "],\"pose_keypoints_3d\":[],\"face_keypoints_3d\":[],\"hand_left_keypoints_3d\":[],"
       "\"hand_right_keypoints_3d\":[]}]}\n";
  return s;
}

nlohmann::ordered_json numbers(const double* v, int n) {
  nlohmann::ordered_json a = nlohmann::ordered_json::array();
  for (int i = 0; i < n; ++i) a.push_back(v[i]);
  return a;
}

std::string calibrationJson(const tools::CameraSet& cams) {
  nlohmann::ordered_json cameras = nlohmann::ordered_json::array();
  for (const tools::Camera& c : cams) {
    nlohmann::ordered_json j;
    j["name"] = c.name;
    j["size"] = {c.width, c.height};
    nlohmann::ordered_json K = nlohmann::ordered_json::array();
    for (int r = 0; r < 3; ++r) {
      const Eigen::Vector3d row = c.K.row(r).transpose();
      K.push_back(numbers(row.data(), 3));
    }
    j["matrix"] = K;
    j["distortions"] = numbers(c.dist.data(), 5);
    const Eigen::AngleAxisd aa(c.R_CW);
    const Vector3d rodrigues = aa.angle() * aa.axis();
    j["rotation"] = numbers(rodrigues.data(), 3);
    j["translation"] = numbers(c.p_CW.data(), 3);
    cameras.push_back(j);
  }
  nlohmann::ordered_json root;
  root["cameras"] = cameras;
  return root.dump(2) + "\n";
}

std::string metaJson(const Recording& r) {
  nlohmann::ordered_json j;
  j["generator"] = "nao_test_recordings";
  j["movement"] = r.movement;
  j["index"] = r.index;
  j["seed"] = r.seed;
  j["recording_seed"] = r.recording_seed;
  j["fps"] = r.fps;
  j["n_frames"] = r.truth.size();
  j["duration_s"] = r.truth.empty() ? 0.0 : r.truth.back().t_s;
  const Subject& b = r.subject;
  j["subject"] = {{"stature_m", b.stature_m},         {"upper_arm_m", b.upper_arm_m}, {"forearm_m", b.forearm_m},
                  {"palm_m", b.palm_m},               {"hand_breadth_m", b.hand_breadth_m},
                  {"shoulder_width_m", b.shoulder_width_m}, {"trunk_m", b.trunk_m}};
  nlohmann::ordered_json motion = nlohmann::ordered_json::object();
  for (const auto& [name, value] : r.params) motion[name] = value;
  j["motion"] = motion;
  j["noise"] = {{"pixel_sigma_px", r.noise.pixel_sigma_px}, {"dropout", r.noise.dropout},
                {"hand_miss", r.noise.hand_miss}, {"confidence_hand", r.noise.confidence_hand}};
  return j.dump(2) + "\n";
}

}  // namespace

bool isMovement(const std::string& name) {
  return std::find(kMovementNames.begin(), kMovementNames.end(), name) != kMovementNames.end();
}

Recording generateRecording(const std::string& movement, int index, std::uint64_t seed) {
  if (!isMovement(movement))
    throw std::invalid_argument("unknown movement '" + movement + "', expected wave, reach or side_raise");
  Recording r;
  r.movement = movement;
  r.index = index;
  r.seed = seed;
  r.fps = kFps;
  char name[64];
  std::snprintf(name, sizeof(name), "%s_%03d", movement.c_str(), index);
  r.name = name;
  const auto m = static_cast<std::uint64_t>(std::find(kMovementNames.begin(), kMovementNames.end(), movement) -
                                            kMovementNames.begin());
  r.recording_seed = splitMix64(splitMix64(splitMix64(seed) ^ (0x100000001b3ULL * (m + 1))) ^
                                static_cast<std::uint64_t>(index));
  Random rng(r.recording_seed);
  r.subject = sampleSubject(rng);
  const Subject& body = r.subject;
  r.cameras = sampleCameras(body, rng);
  r.noise.pixel_sigma_px = rng.uniform(1.0, 2.5);
  r.noise.dropout = rng.uniform(0.005, 0.02);
  r.noise.hand_miss = 0.03;
  for (double& c : r.noise.confidence_body) c = rng.uniform(0.6, 0.92);
  r.noise.confidence_hand = rng.uniform(0.45, 0.75);

  const Motion motion = movement == "wave"    ? waveMotion(rng, r.params)
                        : movement == "reach" ? reachMotion(rng, body, r.params)
                                              : sideRaiseMotion(rng, r.params);
  r.params.emplace_back("stature_m", body.stature_m);

  // Standing: a random spot and heading, swaying a little; small slow drift of the whole arm
  // about the shoulder and a physiological tremor of the forearm.
  const double heading = rng.uniform(-10.0, 10.0) * kDeg, lean = rng.uniform(-2.0, 5.0) * kDeg;
  const Vector3d spot(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.0);
  const Vector3d sway_amp(rng.uniform(0.0, 0.015), rng.uniform(0.0, 0.015), rng.uniform(0.0, 0.003));
  const double sway_hz = rng.uniform(0.1, 0.3), sway_phase = rng.uniform(0.0, 2.0 * kPi);
  const double yaw_sway = rng.uniform(0.0, 3.0) * kDeg;
  Vector3d drift_amp, drift_hz, drift_phase;
  for (int a = 0; a < 3; ++a) {
    drift_amp[a] = rng.uniform(0.3, 1.0) * kDeg;
    drift_hz[a] = rng.uniform(0.1, 0.35);
    drift_phase[a] = rng.uniform(0.0, 2.0 * kPi);
  }
  const double tremor_amp = rng.uniform(0.05, 0.2) * kDeg, tremor_hz = rng.uniform(8.0, 12.0);
  const Matrix3d R_Wfeet = rotation(Vector3d::UnitZ(), heading);
  const Vector3d hip0_W = spot + Vector3d(0.0, 0.0, body.leg_m);
  const Vector3d p_TS(0.0, -0.5 * body.shoulder_width_m, 0.0);
  // Hand points 0 (wrist), 5 (index knuckle, thumb side), 9 (middle knuckle), 17 (little-finger
  // knuckle) in the hand frame: x along the palm, y the palm's normal, z towards the thumb.
  const std::array<Vector3d, 4> p_KHand = {
      Vector3d::Zero(), Vector3d(0.93 * body.palm_m, 0.004, 0.40 * body.hand_breadth_m),
      Vector3d(body.palm_m, 0.0, 0.03 * body.hand_breadth_m),
      Vector3d(0.84 * body.palm_m, -0.004, -0.44 * body.hand_breadth_m)};

  const int n_frames = static_cast<int>(std::floor(motion.duration_s * kFps)) + 1;
  r.truth.resize(static_cast<std::size_t>(n_frames));
  for (int k = 0; k < n_frames; ++k) {
    const double t = k / kFps;
    const double sway = 2.0 * kPi * sway_hz * t;
    const Vector3d hip_W = hip0_W + R_Wfeet * (sway_amp * (std::sin(sway + sway_phase) - std::sin(sway_phase)));
    const Matrix3d R_WT = rotation(Vector3d::UnitZ(), heading + yaw_sway * std::sin(0.7 * sway)) *
                          rotation(Vector3d::UnitY(), lean);
    const Vector3d p_WT = hip_W + R_WT * Vector3d(0.0, 0.0, body.trunk_m);

    ArmPose arm = motion.pose(t);
    Vector3d drift;
    for (int a = 0; a < 3; ++a) drift[a] = drift_amp[a] * std::sin(2.0 * kPi * drift_hz[a] * t + drift_phase[a]);
    if (drift.norm() > 0.0) arm = rotated(rotation(drift, drift.norm()), arm);
    arm.f = (rotation(arm.u, tremor_amp * std::sin(2.0 * kPi * tremor_hz * t)) * arm.f).normalized();

    // Hand frame: the forearm's axis and the palm's normal, then the wrist's flexion (about
    // the thumb axis, towards the palm) and ulnar deviation (about the palm's normal).
    Matrix3d R_TF;
    R_TF.col(0) = arm.f;
    R_TF.col(1) = perpendicular(arm.f, arm.palm);
    R_TF.col(2) = R_TF.col(0).cross(R_TF.col(1));
    const Matrix3d R_TK = R_TF * rotation(Vector3d::UnitZ(), arm.wrist_flex) * rotation(Vector3d::UnitY(), arm.wrist_dev);

    SkeletonFrame& f = r.truth[static_cast<std::size_t>(k)];
    f.t_s = t;
    for (auto& p : f.p_W) p.setZero();
    f.ok.fill(false);
    fillBody(body, R_WT, p_WT, spot, R_Wfeet, f);
    const Vector3d p_TE = p_TS + body.upper_arm_m * arm.u;
    const Vector3d p_TR = p_TE + body.forearm_m * arm.f;
    f.p_W[kRElbow] = R_WT * p_TE + p_WT;
    f.p_W[kRWrist] = R_WT * p_TR + p_WT;
    f.ok[kRElbow] = f.ok[kRWrist] = true;
    for (int h = 0; h < 4; ++h) {
      f.p_W[kRHand0 + h] = R_WT * (p_TR + R_TK * p_KHand[static_cast<std::size_t>(h)]) + p_WT;
      f.ok[kRHand0 + h] = true;
    }
  }
  return r;
}

std::vector<Detections> renderCamera(const Recording& recording, int camera) {
  const tools::Camera& cam = recording.cameras.at(static_cast<std::size_t>(camera));
  Random rng(splitMix64(recording.recording_seed ^ (0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(camera + 1))));
  const Noise& n = recording.noise;
  constexpr double kEdge_px = 40.0;
  auto detect = [&](const Vector3d& p_W, double sigma, double dropout, double confidence) -> Vector3d {
    // Every random number is drawn whether or not it is used, so one point's fate does not
    // shift the others' noise.
    const double u_drop = rng.uniform(), nx = rng.normal(), ny = rng.normal(), nc = rng.normal();
    if (tools::toCamera(cam, p_W).z() < 0.1) return Vector3d::Zero();
    const Eigen::Vector2d px = tools::project(cam, p_W) + sigma * Eigen::Vector2d(nx, ny);
    if (px.x() < 0.0 || px.y() < 0.0 || px.x() >= cam.width || px.y() >= cam.height || u_drop < dropout)
      return Vector3d::Zero();
    const double edge = std::min({px.x(), px.y(), cam.width - px.x(), cam.height - px.y()});
    double c = std::clamp(confidence + 0.05 * nc, 0.05, 0.99);
    if (edge < kEdge_px) c *= 0.6;
    return {px.x(), px.y(), c};
  };
  std::vector<Detections> frames(recording.truth.size());
  for (std::size_t k = 0; k < recording.truth.size(); ++k) {
    const SkeletonFrame& f = recording.truth[k];
    Detections& d = frames[k];
    for (int i = 0; i < kNumBody25; ++i)
      d.pose[static_cast<std::size_t>(i)] = detect(f.p_W[i], n.pixel_sigma_px, n.dropout, n.confidence_body[i]);
    for (auto& h : d.hand_right) h.setZero();
    const bool hand_missed = rng.uniform() < n.hand_miss;
    for (int h = 0; h < 4; ++h) {
      const Vector3d p = detect(f.p_W[kRHand0 + h], 1.5 * n.pixel_sigma_px, 3.0 * n.dropout, n.confidence_hand);
      if (!hand_missed) d.hand_right[static_cast<std::size_t>(kHandKeypointIds[static_cast<std::size_t>(h)])] = p;
    }
  }
  return frames;
}

void writeRecording(const Recording& recording, const std::string& out_dir) {
  const fs::path dir = fs::path(out_dir) / recording.name;
  // A folder left by a longer recording of the same name would add stale frames.
  std::error_code ec;
  fs::remove_all(dir, ec);
  for (std::size_t c = 0; c < recording.cameras.size(); ++c) {
    const fs::path cam_dir = dir / recording.cameras[c].name;
    fs::create_directories(cam_dir, ec);
    if (ec) throw std::runtime_error("cannot create " + cam_dir.string() + ": " + ec.message());
    const std::vector<Detections> frames = renderCamera(recording, static_cast<int>(c));
    for (std::size_t k = 0; k < frames.size(); ++k) {
      char file[160];
      std::snprintf(file, sizeof(file), "%s_%012zu_keypoints.json", recording.name.c_str(), k);
      writeText(cam_dir / file, openPoseJson(frames[k]));
    }
  }
  writeText(dir / "calibration.json", calibrationJson(recording.cameras));
  writeText(dir / "meta.json", metaJson(recording));
  tools::writeSkeletonCsv((dir / "truth.csv").string(), recording.truth);
}

int writeRecordings(const Options& options, std::ostream& progress) {
  if (options.out_dir.empty()) throw std::invalid_argument("no output folder given");
  if (options.per_movement < 1) throw std::invalid_argument("--per-movement must be at least 1");
  if (options.movements.empty()) throw std::invalid_argument("no movement given");
  for (const std::string& m : options.movements)
    if (!isMovement(m)) throw std::invalid_argument("unknown movement '" + m + "', expected wave, reach or side_raise");
  int n = 0;
  for (const std::string& m : options.movements) {
    for (int i = 0; i < options.per_movement; ++i) {
      const Recording r = generateRecording(m, i, options.seed);
      writeRecording(r, options.out_dir);
      progress << r.name << ": " << r.truth.size() << " frames (" << r.truth.back().t_s << " s), stature "
               << r.subject.stature_m << " m\n";
      ++n;
    }
  }
  return n;
}

}  // namespace nao::recordings
