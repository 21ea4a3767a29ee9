// Synthetic demonstrations: subject, motion, cameras and the ground truth (docs/synth.md).
#include "nao/tools/synth.hpp"

#include "nao/tools/command.hpp"
#include "synth_camera.hpp"
#include "synth_random.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace nao::tools {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kFps = 30.0;

Eigen::Matrix3d rotY(double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix(); }
Eigen::Matrix3d rotZ(double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

// Minimum-jerk blend 0 -> 1 over s in [0, 1].
double minimumJerk(double s) {
  s = std::min(1.0, std::max(0.0, s));
  return s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
}

// --- subject ---------------------------------------------------------------------------------

// Segment lengths as fractions of stature H (Winter 2009, Fig. 4.1, after Drillis & Contini
// 1966), each scaled per subject by (1 + N(0, 0.03)) truncated at ±2.5 sd; stature from
// Huston 2009 (US adults, 5th/50th/95th percentiles) as a normal per sex. docs/synth.md.
Anthropometrics sampleBody(SynthRandom& rng) {
  Anthropometrics b;
  b.female = rng.uniform() < 0.5;
  b.stature_m = b.female ? rng.truncatedNormal(1.618, 0.063, 2.5) : rng.truncatedNormal(1.759, 0.067, 2.5);
  const double H = b.stature_m;
  auto frac = [&](double f) { return f * H * rng.truncatedNormal(1.0, 0.03, 2.5); };
  b.upper_arm_m = frac(0.186);
  b.forearm_m = frac(0.146);
  b.hand_length_m = frac(0.108);
  b.shoulder_width_m = frac(0.259) * 0.80;  // biacromial breadth -> shoulder joint centres
  b.hip_width_m = frac(0.191) * 0.85;       // hip breadth -> hip joint centres
  b.trunk_m = frac(0.818 - 0.530);          // shoulder height - hip (greater trochanter) height
  b.leg_m = frac(0.530);
  // Hand points in the hand frame K: palm length (wrist -> middle knuckle) 0.57 of hand
  // length, metacarpal breadth 0.46 of hand length (ANSUR II hand proportions, docs/synth.md).
  const double palm = 0.57 * b.hand_length_m * rng.truncatedNormal(1.0, 0.03, 2.5);
  const double breadth = 0.46 * b.hand_length_m * rng.truncatedNormal(1.0, 0.03, 2.5);
  b.p_KHand[0] = Eigen::Vector3d::Zero();                           // 0: wrist
  b.p_KHand[1] = Eigen::Vector3d(0.95 * palm, 0.0, 0.38 * breadth);  // 5: index knuckle (thumb side, +z)
  b.p_KHand[2] = Eigen::Vector3d(palm, 0.0, 0.0);                    // 9: middle knuckle, on the hand's x axis
  b.p_KHand[3] = Eigen::Vector3d(0.86 * palm, 0.0, -0.42 * breadth);  // 17: little-finger knuckle
  b.hand_segment_m = (0.25 * (b.p_KHand[0] + b.p_KHand[1] + b.p_KHand[2] + b.p_KHand[3])).norm();
  return b;
}

// --- motion ----------------------------------------------------------------------------------

HumanJointVector uniformJoints(SynthRandom& rng, const HumanJointVector& lo_deg, const HumanJointVector& hi_deg) {
  HumanJointVector q;
  for (int j = 0; j < kNumHumanJoints; ++j) q[j] = rng.uniform(lo_deg[j], hi_deg[j]) * kDeg;
  return q;
}

HumanJointVector jointsDeg(double a, double b, double c, double d, double e, double f, double g) {
  HumanJointVector q;
  q << a, b, c, d, e, f, g;
  return q;
}

MotionParams sampleMotion(Movement movement, const Anthropometrics& body, SynthRandom& rng) {
  MotionParams m;
  m.t_idle_start_s = rng.uniform(0.4, 1.0);
  m.t_raise_s = rng.uniform(1.4, 2.6);
  m.t_lower_s = rng.uniform(1.4, 2.6);
  m.t_idle_end_s = rng.uniform(0.4, 1.0);
  m.circle_period_s = rng.uniform(1.6, 3.0);
  m.n_loops = 3 + static_cast<int>(rng.uniform() * 2.0);  // 3 or 4
  m.direction = rng.uniform() < 0.5 ? 1.0 : -1.0;
  m.phase0_rad = rng.uniform(0.0, 2.0 * kPi);
  // Arm hanging: pitch ~ 90°, humerus turned so that the elbow would flex forward (NAO's own
  // rest posture has RElbowYaw ~ 70°), palm towards the thigh.
  m.q_rest = uniformJoints(rng, jointsDeg(80, -12, 60, 8, -50, -5, 0), jointsDeg(88, -4, 85, 20, -20, 5, 8));
  switch (movement) {
    case Movement::kWholeArm:
      // Near-straight arm circling about a direction in front of the shoulder.
      m.q_centre = uniformJoints(rng, jointsDeg(-20, -35, 20, 8, -40, -10, 0), jointsDeg(35, -10, 70, 25, 10, 10, 10));
      m.radius_rad = rng.uniform(12.0, 28.0) * kDeg;
      m.radius_m = std::sin(m.radius_rad) * (body.upper_arm_m + body.forearm_m + body.hand_segment_m);
      break;
    case Movement::kElbow:
      // Upper arm held forward; the forearm circles about the elbow around a direction
      // pointing up and inward (elbow flexion 70-100°).
      m.q_centre = uniformJoints(rng, jointsDeg(-5, -45, 60, 70, -40, -10, 0), jointsDeg(30, -10, 100, 100, 10, 10, 10));
      m.radius_rad = rng.uniform(15.0, 30.0) * kDeg;
      m.radius_m = std::sin(m.radius_rad) * (body.forearm_m + body.hand_segment_m);
      break;
    case Movement::kWrist:
      // Forearm held up in front; the hand circles about the wrist (flexion x deviation).
      m.q_centre = uniformJoints(rng, jointsDeg(0, -30, 40, 60, -70, -5, 0), jointsDeg(30, -5, 90, 100, 0, 5, 8));
      m.radius_rad = rng.uniform(20.0, 35.0) * kDeg;
      m.radius_m = std::sin(m.radius_rad) * body.hand_segment_m;
      break;
  }
  for (int j = 0; j < kNumHumanJoints; ++j) {
    m.drift_amp[j] = rng.uniform(0.5, 1.5) * kDeg;
    m.drift_hz[j] = rng.uniform(0.1, 0.35);
    m.drift_phase[j] = rng.uniform(0.0, 2.0 * kPi);
    m.tremor_amp[j] = rng.uniform(0.05, 0.2) * kDeg;
    m.tremor_hz[j] = rng.uniform(8.0, 12.0);
    m.tremor_phase[j] = rng.uniform(0.0, 2.0 * kPi);
  }
  m.sway_amp_m = Eigen::Vector3d(rng.uniform(0.0, 0.02), rng.uniform(0.0, 0.02), rng.uniform(0.0, 0.004));
  m.sway_hz = rng.uniform(0.1, 0.3);
  m.sway_phase = rng.uniform(0.0, 2.0 * kPi);
  m.yaw_sway_rad = rng.uniform(0.0, 4.0) * kDeg;
  m.lean_rad = rng.uniform(-2.0, 6.0) * kDeg;
  return m;
}

double circleDuration(const MotionParams& m) { return m.n_loops * m.circle_period_s + 0.25 * m.circle_period_s; }

// Angle travelled on the circle after tau seconds of the circle phase: speed ramps linearly
// up over the first quarter period and down over the last, so the velocity is continuous with
// the raise and lower phases; the total is exactly n_loops turns.
double circleAngle(const MotionParams& m, double tau) {
  const double T = circleDuration(m), Tr = 0.25 * m.circle_period_s, w = 2.0 * kPi / m.circle_period_s;
  tau = std::min(T, std::max(0.0, tau));
  if (tau < Tr) return w * tau * tau / (2.0 * Tr);
  if (tau <= T - Tr) return w * (tau - 0.5 * Tr);
  const double r = T - tau;
  return 2.0 * kPi * m.n_loops - w * r * r / (2.0 * Tr);
}

// Unit vector on a cone of half-angle `radius` about `centre`, at angle phi from the
// direction `ref` (projected perpendicular to the centre).
Eigen::Vector3d onCone(const Eigen::Vector3d& centre, const Eigen::Vector3d& ref, double radius, double phi) {
  const Eigen::Vector3d b1 = (ref - centre * centre.dot(ref)).normalized();
  const Eigen::Vector3d b2 = centre.cross(b1);
  return std::cos(radius) * centre + std::sin(radius) * (std::cos(phi) * b1 + std::sin(phi) * b2);
}

// Joint values on the circle at angle phi (rad travelled), before drift and tremor.
HumanJointVector circleJoints(Movement movement, const MotionParams& m, double phi) {
  const double a = m.phase0_rad + m.direction * phi;
  HumanJointVector q = m.q_centre;
  switch (movement) {
    case Movement::kWholeArm: {
      // The upper arm's direction circles on a cone about the centre posture's direction.
      const Eigen::Vector3d c = rotY(m.q_centre[kHumanShoulderPitch]) * rotZ(m.q_centre[kHumanShoulderRoll]) * Eigen::Vector3d::UnitX();
      const Eigen::Vector3d u = onCone(c, Eigen::Vector3d::UnitZ(), m.radius_rad, a);
      q[kHumanShoulderPitch] = std::atan2(-u.z(), u.x());
      q[kHumanShoulderRoll] = std::asin(u.y());
      break;
    }
    case Movement::kElbow: {
      // The forearm direction (upper-arm frame before humeral rotation) circles on a cone.
      const double e0 = m.q_centre[kHumanElbowRoll], y0 = m.q_centre[kHumanElbowYaw];
      const Eigen::Vector3d c(std::cos(e0), std::sin(e0) * std::cos(y0), std::sin(e0) * std::sin(y0));
      const Eigen::Vector3d f = onCone(c, Eigen::Vector3d::UnitX(), m.radius_rad, a);
      q[kHumanElbowRoll] = std::acos(f.x());
      q[kHumanElbowYaw] = std::atan2(f.z(), f.y());
      // The elbow is not perfectly still: a small sympathetic shoulder motion.
      q[kHumanShoulderPitch] += 0.12 * m.radius_rad * std::sin(a);
      q[kHumanShoulderRoll] += 0.08 * m.radius_rad * std::cos(a);
      break;
    }
    case Movement::kWrist:
      // Circumduction: flexion and deviation in quadrature (deviation's range is about half
      // of flexion's), with a little sympathetic elbow motion.
      q[kHumanWristFlex] += m.radius_rad * std::cos(a);
      q[kHumanWristDev] += 0.5 * m.radius_rad * std::sin(a);
      q[kHumanElbowRoll] += 0.10 * m.radius_rad * std::sin(a);
      break;
  }
  return q;
}

// --- cameras ---------------------------------------------------------------------------------

// Two cameras in front of the subject, one to each side, aimed at the chest (docs/synth.md).
CameraSet sampleCameras(const Anthropometrics& body, SynthRandom& rng) {
  CameraSet cams;
  for (int i = 0; i < 2; ++i) {
    Camera c = sampleLabIntrinsics(i, rng);
    const double azimuth = (i == 0 ? -1.0 : 1.0) * rng.uniform(25.0, 35.0) * kDeg;
    const double distance = rng.uniform(2.8, 3.4);
    const Eigen::Vector3d centre_W(distance * std::cos(azimuth), distance * std::sin(azimuth), rng.uniform(1.2, 1.6));
    const Eigen::Vector3d target_W(0.0, -0.15, 0.72 * body.stature_m);
    // Camera axes: z optical (towards the target), y down in the image, x right.
    const Eigen::Vector3d z_C = (target_W - centre_W).normalized();
    const Eigen::Vector3d x_C = z_C.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d y_C = z_C.cross(x_C);
    Eigen::Matrix3d R_WC;
    R_WC.col(0) = x_C;
    R_WC.col(1) = y_C;
    R_WC.col(2) = z_C;
    R_WC = R_WC * rotZ(rng.normal(0.0, 0.5 * kDeg));  // a slightly tilted mount
    // Store the rotation through its Rodrigues vector so that the written calibration
    // describes exactly the camera that produced the pixels.
    const Eigen::AngleAxisd aa(Eigen::Matrix3d(R_WC.transpose()));
    c.R_CW = Eigen::AngleAxisd(aa.angle(), aa.axis()).toRotationMatrix();
    c.p_CW = -(c.R_CW * centre_W);
    cams.push_back(c);
  }
  return cams;
}

// --- body points -----------------------------------------------------------------------------

// Static body points (everything but the right arm) in the torso frame T.
void fillBody(const Anthropometrics& b, const Eigen::Matrix3d& R_WT, const Eigen::Vector3d& p_WT,
              SkeletonFrame& f) {
  const double H = b.stature_m, sw = 0.5 * b.shoulder_width_m, hw = 0.5 * b.hip_width_m;
  auto put = [&](int i, const Eigen::Vector3d& p_T) {
    f.p_W[i] = R_WT * p_T + p_WT;
    f.ok[i] = true;
  };
  put(kNeck, Eigen::Vector3d(-0.01 * H, 0.0, 0.02 * H));
  put(kNose, Eigen::Vector3d(0.055 * H, 0.0, 0.088 * H));
  put(kREye, Eigen::Vector3d(0.045 * H, -0.018 * H, 0.118 * H));
  put(kLEye, Eigen::Vector3d(0.045 * H, 0.018 * H, 0.118 * H));
  put(kREar, Eigen::Vector3d(-0.005 * H, -0.045 * H, 0.108 * H));
  put(kLEar, Eigen::Vector3d(-0.005 * H, 0.045 * H, 0.108 * H));
  put(kRShoulder, Eigen::Vector3d(0.0, -sw, 0.0));
  put(kLShoulder, Eigen::Vector3d(0.0, sw, 0.0));
  // Left arm hanging relaxed beside the body.
  const Eigen::Vector3d p_TLE = Eigen::Vector3d(0.0, sw, 0.0) + b.upper_arm_m * Eigen::Vector3d(0.05, 0.04, -1.0).normalized();
  put(kLElbow, p_TLE);
  put(kLWrist, p_TLE + b.forearm_m * Eigen::Vector3d(0.25, 0.0, -1.0).normalized());
  put(kMidHip, Eigen::Vector3d(0.0, 0.0, -b.trunk_m));
  put(kRHip, Eigen::Vector3d(0.0, -hw, -b.trunk_m));
  put(kLHip, Eigen::Vector3d(0.0, hw, -b.trunk_m));
}

// Legs: feet stay where they stood at the start; knees between hips and ankles, slightly forward.
void fillLegs(const Anthropometrics& b, SkeletonFrame& f) {
  const double H = b.stature_m, hw = 0.5 * b.hip_width_m, foot = 0.152 * H, ankle_z = 0.039 * H;
  const int hip[2] = {kRHip, kLHip}, knee[2] = {kRKnee, kLKnee}, ankle[2] = {kRAnkle, kLAnkle};
  const int heel[2] = {kRHeel, kLHeel}, big[2] = {kRBigToe, kLBigToe}, small[2] = {kRSmallToe, kLSmallToe};
  for (int s = 0; s < 2; ++s) {
    const double side = s == 0 ? -1.0 : 1.0;
    const Eigen::Vector3d p_ankle(0.0, side * hw, ankle_z);
    f.p_W[ankle[s]] = p_ankle;
    f.p_W[knee[s]] = 0.5 * (f.p_W[hip[s]] + p_ankle) + Eigen::Vector3d(0.015, 0.0, 0.0);
    f.p_W[heel[s]] = p_ankle + Eigen::Vector3d(-0.25 * foot, 0.0, -0.8 * ankle_z);
    f.p_W[big[s]] = p_ankle + Eigen::Vector3d(0.75 * foot, -side * 0.01, -0.8 * ankle_z);
    f.p_W[small[s]] = p_ankle + Eigen::Vector3d(0.65 * foot, side * 0.035, -0.8 * ankle_z);
    for (int i : {knee[s], ankle[s], heel[s], big[s], small[s]}) f.ok[i] = true;
  }
}

}  // namespace

Movement parseMovement(const std::string& name) {
  for (int m = 0; m < 3; ++m)
    if (name == kMovementNames[m]) return static_cast<Movement>(m);
  throw UserError("unknown movement '" + name + "', expected whole_arm, elbow or wrist");
}

std::uint64_t demoSeed(std::uint64_t seed, Movement movement, int index) {
  std::uint64_t s = splitMix64(seed);
  s = splitMix64(s ^ (0x100000001b3ULL * static_cast<std::uint64_t>(static_cast<int>(movement) + 1)));
  return splitMix64(s ^ static_cast<std::uint64_t>(index));
}

HumanArmPoints humanArmForward(const Anthropometrics& body, const Eigen::Matrix3d& R_WT, const Eigen::Vector3d& p_WT,
                               const Eigen::Vector3d& p_TS, const HumanJointVector& q) {
  using Eigen::AngleAxisd;
  using Eigen::Vector3d;
  // NAO's chain with human lengths: pitch(Y) roll(Z) yaw(X) | roll(Z) yaw(X) | flex(Z) dev(Y).
  const Eigen::Matrix3d R_TU = (AngleAxisd(q[kHumanShoulderPitch], Vector3d::UnitY()) *
                                AngleAxisd(q[kHumanShoulderRoll], Vector3d::UnitZ()) *
                                AngleAxisd(q[kHumanElbowYaw], Vector3d::UnitX()))
                                   .toRotationMatrix();
  const Eigen::Matrix3d R_TF =
      R_TU * (AngleAxisd(q[kHumanElbowRoll], Vector3d::UnitZ()) * AngleAxisd(q[kHumanWristYaw], Vector3d::UnitX()))
                 .toRotationMatrix();
  const Eigen::Matrix3d R_TK =
      R_TF * (AngleAxisd(q[kHumanWristFlex], Vector3d::UnitZ()) * AngleAxisd(q[kHumanWristDev], Vector3d::UnitY()))
                 .toRotationMatrix();
  const Vector3d p_TE = p_TS + R_TU * Vector3d(body.upper_arm_m, 0.0, 0.0);
  const Vector3d p_TR = p_TE + R_TF * Vector3d(body.forearm_m, 0.0, 0.0);
  HumanArmPoints out;
  out.p_WE = R_WT * p_TE + p_WT;
  out.p_WR = R_WT * p_TR + p_WT;
  for (int k = 0; k < 4; ++k) out.p_WHand[k] = R_WT * (p_TR + R_TK * body.p_KHand[k]) + p_WT;
  return out;
}

SynthDemo generateDemo(Movement movement, int index, std::uint64_t seed, bool noise_free) {
  SynthDemo d;
  d.movement = movement;
  d.index = index;
  d.seed = seed;
  d.noise_free = noise_free;
  d.fps = kFps;
  char name[64];
  std::snprintf(name, sizeof(name), "%s_%03d", kMovementNames[static_cast<int>(movement)], index);
  d.name = name;
  d.demo_seed = demoSeed(seed, movement, index);
  SynthRandom rng(d.demo_seed);
  d.body = sampleBody(rng);
  d.motion = sampleMotion(movement, d.body, rng);
  d.cameras = sampleCameras(d.body, rng);
  // Camera noise: sampled here so that it belongs to the demonstration, applied at rendering.
  d.noise.pixel_sigma_px = rng.uniform(1.0, 2.5);
  d.noise.dropout_prob = rng.uniform(0.005, 0.02);
  for (double& c : d.noise.confidence_body) c = rng.uniform(0.65, 0.92);
  d.noise.confidence_hand = rng.uniform(0.45, 0.75);

  const MotionParams& m = d.motion;
  const double t_circle0 = m.t_idle_start_s + m.t_raise_s;
  const double t_circle1 = t_circle0 + circleDuration(m);
  const double t_lower1 = t_circle1 + m.t_lower_s;
  const double t_end = t_lower1 + m.t_idle_end_s;
  const int n_frames = static_cast<int>(std::floor(t_end * kFps)) + 1;
  const HumanJointVector q_start = circleJoints(movement, m, 0.0);
  const HumanJointVector q_finish = circleJoints(movement, m, 2.0 * kPi * m.n_loops);
  const Eigen::Vector3d p_TS(0.0, -0.5 * d.body.shoulder_width_m, 0.0);
  const Eigen::Vector3d hip0_W(0.0, 0.0, d.body.leg_m);

  d.truth.resize(n_frames);
  d.q.resize(n_frames);
  d.phase.resize(n_frames);
  for (int k = 0; k < n_frames; ++k) {
    const double t = k / kFps;
    HumanJointVector q;
    int phase;
    if (t < t_circle0) {
      phase = 0;
      q = m.q_rest + (q_start - m.q_rest) * minimumJerk((t - m.t_idle_start_s) / m.t_raise_s);
    } else if (t < t_circle1) {
      phase = 1;
      q = circleJoints(movement, m, circleAngle(m, t - t_circle0));
    } else {
      phase = 2;
      q = q_finish + (m.q_rest - q_finish) * minimumJerk((t - t_circle1) / m.t_lower_s);
    }
    for (int j = 0; j < kNumHumanJoints; ++j) {
      q[j] += m.drift_amp[j] * std::sin(2.0 * kPi * m.drift_hz[j] * t + m.drift_phase[j]);
      if (!noise_free) q[j] += m.tremor_amp[j] * std::sin(2.0 * kPi * m.tremor_hz[j] * t + m.tremor_phase[j]);
    }

    // Torso: standing, swaying a little; at t = 0 it faces +x with the pelvis above the origin.
    const double sway = 2.0 * kPi * m.sway_hz * t;
    const Eigen::Vector3d hip_W =
        hip0_W + m.sway_amp_m * (std::sin(sway + m.sway_phase) - std::sin(m.sway_phase));
    const double yaw = m.yaw_sway_rad * (std::sin(0.7 * sway + m.sway_phase) - std::sin(m.sway_phase));
    const Eigen::Matrix3d R_WT = rotZ(yaw) * rotY(m.lean_rad);
    const Eigen::Vector3d p_WT = hip_W + R_WT * Eigen::Vector3d(0.0, 0.0, d.body.trunk_m);

    SkeletonFrame& f = d.truth[k];
    f.t_s = t;
    for (auto& p : f.p_W) p.setZero();
    f.ok.fill(false);
    fillBody(d.body, R_WT, p_WT, f);
    fillLegs(d.body, f);
    const HumanArmPoints arm = humanArmForward(d.body, R_WT, p_WT, p_TS, q);
    f.p_W[kRElbow] = arm.p_WE;
    f.p_W[kRWrist] = arm.p_WR;
    f.ok[kRElbow] = f.ok[kRWrist] = true;
    for (int h = 0; h < 4; ++h) {
      f.p_W[kRHand0 + h] = arm.p_WHand[h];
      f.ok[kRHand0 + h] = true;
    }
    d.q[k] = q;
    d.phase[k] = phase;
  }
  return d;
}

std::vector<OpenPoseFrame> renderCamera(const SynthDemo& demo, int camera_index) {
  const Camera& cam = demo.cameras.at(static_cast<std::size_t>(camera_index));
  SynthRandom rng(splitMix64(demo.demo_seed ^ (0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(camera_index + 1))));
  const NoiseParams& n = demo.noise;
  constexpr double kEdge_px = 40.0;

  auto detect = [&](const Eigen::Vector3d& p_W, double sigma, double drop, double conf_mean) -> Eigen::Vector3d {
    const Eigen::Vector3d p_C = toCamera(cam, p_W);
    if (p_C.z() < 0.1) return Eigen::Vector3d::Zero();
    Eigen::Vector2d px = project(cam, p_W);
    if (demo.noise_free) {
      if (px.x() < 0.0 || px.y() < 0.0 || px.x() >= cam.width || px.y() >= cam.height) return Eigen::Vector3d::Zero();
      return Eigen::Vector3d(px.x(), px.y(), 1.0);
    }
    // Draw every random number whether or not it is used, so one point's fate does not shift
    // the others' noise.
    const double u_drop = rng.uniform(), nx = rng.normal(), ny = rng.normal(), nc = rng.normal();
    px += sigma * Eigen::Vector2d(nx, ny);
    if (px.x() < 0.0 || px.y() < 0.0 || px.x() >= cam.width || px.y() >= cam.height || u_drop < drop)
      return Eigen::Vector3d::Zero();
    const double edge = std::min({px.x(), px.y(), cam.width - px.x(), cam.height - px.y()});
    double c = std::min(0.99, std::max(0.05, conf_mean + 0.05 * nc));
    if (edge < kEdge_px) c *= 0.6;
    return Eigen::Vector3d(px.x(), px.y(), c);
  };

  std::vector<OpenPoseFrame> frames(demo.truth.size());
  for (std::size_t k = 0; k < demo.truth.size(); ++k) {
    const SkeletonFrame& f = demo.truth[k];
    OpenPoseFrame& o = frames[k];
    for (int i = 0; i < kNumBody25; ++i)
      o.pose[i] = detect(f.p_W[i], n.pixel_sigma_px, n.dropout_prob, n.confidence_body[i]);
    for (auto& h : o.hand_right) h.setZero();
    // OpenPose's hand detector misses the whole hand now and then.
    const bool hand_missed = !demo.noise_free && rng.uniform() < 0.03;
    for (int h = 0; h < 4; ++h) {
      const Eigen::Vector3d p = detect(f.p_W[kRHand0 + h], 1.5 * n.pixel_sigma_px, 3.0 * n.dropout_prob, n.confidence_hand);
      if (!hand_missed) o.hand_right[kHandKeypointIds[h]] = p;
    }
  }
  return frames;
}

}  // namespace nao::tools
