// Human kinematics: torso frame, NAO-convention joint angles, d_h and the scaled endpoint,
// cross-checked against the synthesiser's forward model (an independent AngleAxis chain).
#include "nao/human_kinematics.hpp"
#include "nao/tools/human_scale.hpp"
#include "nao/tools/synth.hpp"
#include "support/test_util.hpp"

#include <Eigen/Geometry>
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace nao;
using nao::test::kDeg;
using nao::tools::Movement;

namespace {

constexpr double kPi = 3.14159265358979323846;

double angleDiff(double a, double b) { return std::abs(std::remainder(a - b, 2.0 * kPi)); }

// A full skeleton frame (torso points from the pose, the right arm from humanArmForward).
SkeletonFrame poseFrame(const tools::Anthropometrics& body, const Eigen::Matrix3d& R_WT, const Eigen::Vector3d& p_WT,
                        const HumanJointVector& q) {
  SkeletonFrame f;
  for (auto& p : f.p_W) p.setZero();
  f.ok.fill(false);
  const Eigen::Vector3d p_TS(0.0, -0.5 * body.shoulder_width_m, 0.0);
  auto put = [&](int i, const Eigen::Vector3d& p_W) {
    f.p_W[i] = p_W;
    f.ok[i] = true;
  };
  put(kRShoulder, R_WT * p_TS + p_WT);
  put(kLShoulder, R_WT * Eigen::Vector3d(0.0, 0.5 * body.shoulder_width_m, 0.0) + p_WT);
  put(kNeck, R_WT * Eigen::Vector3d(-0.02, 0.0, 0.04) + p_WT);
  put(kMidHip, R_WT * Eigen::Vector3d(0.0, 0.0, -body.trunk_m) + p_WT);
  put(kRHip, R_WT * Eigen::Vector3d(0.0, -0.5 * body.hip_width_m, -body.trunk_m) + p_WT);
  put(kLHip, R_WT * Eigen::Vector3d(0.0, 0.5 * body.hip_width_m, -body.trunk_m) + p_WT);
  const tools::HumanArmPoints arm = tools::humanArmForward(body, R_WT, p_WT, p_TS, q);
  put(kRElbow, arm.p_WE);
  put(kRWrist, arm.p_WR);
  for (int h = 0; h < 4; ++h) put(kRHand0 + h, arm.p_WHand[h]);
  return f;
}

HumanJointVector randomHumanPose(std::mt19937_64& rng) {
  // Anatomical ranges away from the documented singularities (roll ±90°, elbow < 3°, flexion ±90°).
  const double lo[kNumHumanJoints] = {-170, -80, -170, 5, -100, -70, -30};
  const double hi[kNumHumanJoints] = {170, 35, 170, 150, 100, 70, 40};
  HumanJointVector q;
  for (int j = 0; j < kNumHumanJoints; ++j) q[j] = std::uniform_real_distribution<double>(lo[j], hi[j])(rng) * kDeg;
  return q;
}

Eigen::Matrix3d randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond qt(n(rng), n(rng), n(rng), n(rng));
  return qt.normalized().toRotationMatrix();
}

}  // namespace

TEST_CASE("joint angles recovered from noise-free keypoints of all 240 demonstrations match the model's joint values within 0.5 deg") {
  // All seven DoFs are determined here: every synthesised frame sees the hand and keeps the
  // elbow bent (>= 6.5°), so none is excluded; the test asserts that no frame is flagged.
  // The set is the paper-sized one: --per-movement 80 --seed 1.
  const HumanKinematicsConfig config;
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    double max_err[kNumHumanJoints] = {};
    int n_frames = 0;
    for (int index = 0; index < 80; ++index) {
      const tools::SynthDemo demo = tools::generateDemo(m, index, 1, true);
      HumanArmData data;
      for (std::size_t k = 0; k < demo.truth.size(); ++k) {
        humanArmKinematics(config, data, demo.truth[k]);
        REQUIRE_MESSAGE(data.valid, demo.name << " frame " << k << ": expected a valid frame, flags " << data.flags);
        REQUIRE_MESSAGE(data.flags == 0u, demo.name << " frame " << k << ": expected no flag, got " << data.flags);
        for (int j = 0; j < kNumHumanJoints; ++j) max_err[j] = std::max(max_err[j], angleDiff(data.q[j], demo.q[k][j]));
        ++n_frames;
      }
    }
    for (int j = 0; j < kNumHumanJoints; ++j)
      CHECK_MESSAGE(max_err[j] < 0.5 * kDeg, std::string(tools::kMovementNames[static_cast<int>(m)]) << " " << std::string(kHumanJointNames[j])
                                                 << ": expected max error < 0.5 deg over " << n_frames
                                                 << " frames, got " << max_err[j] / kDeg << " deg");
  }
}

TEST_CASE("joint angles of randomly sampled arm poses and torso poses are recovered exactly") {
  std::mt19937_64 rng(5);
  const HumanKinematicsConfig config;
  std::vector<tools::Anthropometrics> bodies;
  for (int i = 0; i < 20; ++i) bodies.push_back(tools::generateDemo(Movement::kWholeArm, i, 3, true).body);
  double max_err = 0.0;
  for (int i = 0; i < 5000; ++i) {
    const tools::Anthropometrics& body = bodies[static_cast<std::size_t>(i) % bodies.size()];
    const HumanJointVector q = randomHumanPose(rng);
    const Eigen::Matrix3d R_WT = randomRotation(rng);
    const Eigen::Vector3d p_WT = Eigen::Vector3d::Random() * 3.0;
    HumanArmData data;
    humanArmKinematics(config, data, poseFrame(body, R_WT, p_WT, q));
    REQUIRE(data.valid);
    REQUIRE(data.hand_seen);
    for (int j = 0; j < kNumHumanJoints; ++j) max_err = std::max(max_err, angleDiff(data.q[j], q[j]));
  }
  CHECK_MESSAGE(max_err < 1e-6, "expected every angle within 1e-6 rad, got " << max_err);
}

TEST_CASE("the torso frame and the angles do not change when the subject walks or turns") {
  const tools::SynthDemo demo = tools::generateDemo(Movement::kElbow, 2, 21, true);
  const HumanKinematicsConfig config;
  std::mt19937_64 rng(9);
  for (std::size_t k = 0; k < demo.truth.size(); k += 17) {
    HumanArmData a, b;
    humanArmKinematics(config, a, demo.truth[k]);
    // Any turn about the vertical plus a lean, and a walk of a few metres.
    const double yaw = std::uniform_real_distribution<double>(-kPi, kPi)(rng);
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()))
                                  .toRotationMatrix();
    const Eigen::Vector3d t(std::uniform_real_distribution<double>(-5, 5)(rng), std::uniform_real_distribution<double>(-5, 5)(rng), 0.1);
    SkeletonFrame moved = demo.truth[k];
    for (auto& p : moved.p_W) p = R * p + t;
    humanArmKinematics(config, b, moved);
    REQUIRE(b.valid);
    CHECK_MESSAGE((a.q - b.q).cwiseAbs().maxCoeff() < 1e-9, "frame " << k << ": angles expected " << a.q.transpose()
                                                                      << ", got " << b.q.transpose());
    CHECK_MESSAGE((a.p_SH_T - b.p_SH_T).norm() < 1e-9, "frame " << k << ": p_h expected " << a.p_SH_T.transpose()
                                                                 << ", got " << b.p_SH_T.transpose());
    CHECK(std::abs(a.d_h_m - b.d_h_m) < 1e-9);
    CHECK((R * a.R_WT - b.R_WT).cwiseAbs().maxCoeff() < 1e-9);
  }
}

TEST_CASE("the torso frame from both hips equals the one from MidHip, and the neck point is not used") {
  const tools::SynthDemo demo = tools::generateDemo(Movement::kWholeArm, 0, 4, true);
  const SkeletonFrame& f = demo.truth[100];
  Eigen::Matrix3d R_mid, R_hips;
  Eigen::Vector3d p_mid, p_hips;
  REQUIRE(humanTorsoFrame(f, R_mid, p_mid));
  SkeletonFrame g = f;
  g.ok[kMidHip] = false;
  g.p_W[kNeck] += Eigen::Vector3d(0.1, -0.2, 0.3);  // a neck point from another layout
  REQUIRE(humanTorsoFrame(g, R_hips, p_hips));
  CHECK((R_mid - R_hips).cwiseAbs().maxCoeff() < 1e-12);
  CHECK((p_mid - p_hips).norm() < 1e-12);
  // The frame is a proper rotation: x forward, y left, z up for the synthesised subject.
  CHECK(std::abs(R_mid.determinant() - 1.0) < 1e-12);
  CHECK(R_mid(2, 2) > 0.9);  // z up
  CHECK(R_mid(0, 0) > 0.9);  // facing +x at the start
}

TEST_CASE("d_h is the sum of the sampled segment lengths and p_r has the length ratio d_r/d_h") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const double d_r = robotScale(arm);
  const HumanKinematicsConfig config;
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    for (int index = 0; index < 4; ++index) {
      const tools::SynthDemo demo = tools::generateDemo(m, index, 8, true);
      const double d_h = demo.body.upper_arm_m + demo.body.forearm_m + demo.body.hand_segment_m;
      HumanArmData data;
      for (std::size_t k = 0; k < demo.truth.size(); k += 7) {
        humanArmKinematics(config, data, demo.truth[k]);
        REQUIRE(data.valid);
        CHECK_MESSAGE(std::abs(data.d_h_m - d_h) < 1e-9, demo.name << ": d_h expected " << d_h << ", got " << data.d_h_m);
        const Eigen::Vector3d p_r = scaleHumanEndpoint(d_r, data.d_h_m, data.p_SH_T);
        CHECK_MESSAGE(std::abs(p_r.norm() / data.p_SH_T.norm() - d_r / d_h) < 1e-12,
                      "expected |p_r|/|p_h| = " << d_r / d_h << ", got " << p_r.norm() / data.p_SH_T.norm());
        CHECK(p_r.normalized().dot(data.p_SH_T.normalized()) > 1.0 - 1e-12);
        // The endpoint is the hand keypoints' centre.
        Eigen::Vector3d c_W = Eigen::Vector3d::Zero();
        for (int h = 0; h < 4; ++h) c_W += 0.25 * demo.truth[k].p_W[kRHand0 + h];
        CHECK((data.R_WT * data.p_TH + data.p_WT - c_W).norm() < 1e-12);
      }
      // The demonstration aggregate (medians) gives the same d_h.
      const tools::HumanArmLengths lengths = tools::estimateHumanArmLengths(demo.truth);
      CHECK(lengths.n_arm_frames == static_cast<int>(demo.truth.size()));
      CHECK_MESSAGE(std::abs(lengths.scale_m - d_h) < 1e-9, "median d_h expected " << d_h << ", got " << lengths.scale_m);
      CHECK(std::abs(lengths.upper_arm_m - demo.body.upper_arm_m) < 1e-9);
      CHECK(std::abs(lengths.forearm_m - demo.body.forearm_m) < 1e-9);
      CHECK(std::abs(lengths.hand_m - demo.body.hand_segment_m) < 1e-9);
    }
  }
  // An unusable scale gives no target at all (NaN), never a plausible point like the shoulder.
  CHECK_FALSE(scaleHumanEndpoint(d_r, 0.0, Eigen::Vector3d::Ones()).allFinite());
}

TEST_CASE("without the hand the endpoint extends the forearm by the configured hand length and the wrist DoFs are held") {
  const tools::SynthDemo demo = tools::generateDemo(Movement::kWrist, 1, 2, true);
  HumanKinematicsConfig config;
  config.hand_length_m = demo.body.hand_segment_m;
  HumanArmData data;
  humanArmKinematics(config, data, demo.truth[200]);
  REQUIRE(data.hand_seen);
  const HumanJointVector q_before = data.q;
  SkeletonFrame f = demo.truth[260];
  f.ok[kRHand9] = false;
  humanArmKinematics(config, data, f);
  REQUIRE(data.valid);
  CHECK_FALSE(data.hand_seen);
  CHECK((data.flags & kHumanNoHand) != 0u);
  for (int j : {kHumanWristYaw, kHumanWristFlex, kHumanWristDev})
    CHECK_MESSAGE(data.q[j] == q_before[j], std::string(kHumanJointNames[j]) << ": expected the held " << q_before[j] << ", got " << data.q[j]);
  for (int j : {kHumanShoulderPitch, kHumanShoulderRoll, kHumanElbowYaw, kHumanElbowRoll})
    CHECK(angleDiff(data.q[j], demo.q[260][j]) < 1e-9);
  const Eigen::Vector3d f_T = (data.p_TR - data.p_TE).normalized();
  CHECK((data.p_TH - (data.p_TR + config.hand_length_m * f_T)).norm() < 1e-12);
  CHECK(std::abs(data.d_h_m - demo.body.scale_m()) < 1e-9);
  // Without a configured hand length: the documented fraction of the forearm.
  config.hand_length_m = 0.0;
  humanArmKinematics(config, data, f);
  CHECK(std::abs(data.l_hand_m - config.hand_to_forearm * data.l_forearm_m) < 1e-12);
}

TEST_CASE("a straight elbow holds ElbowYaw and flags it") {
  std::mt19937_64 rng(3);
  const tools::Anthropometrics body = tools::generateDemo(Movement::kWholeArm, 0, 1, true).body;
  HumanJointVector q = randomHumanPose(rng);
  const HumanKinematicsConfig config;
  HumanArmData data;
  humanArmKinematics(config, data, poseFrame(body, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 1.4), q));
  REQUIRE(data.flags == 0u);
  const double yaw_before = data.q[kHumanElbowYaw];
  HumanJointVector q2 = q;
  q2[kHumanElbowRoll] = 1.0 * kDeg;
  q2[kHumanElbowYaw] += 0.7;
  humanArmKinematics(config, data, poseFrame(body, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 1.4), q2));
  REQUIRE(data.valid);
  CHECK((data.flags & kHumanElbowStraight) != 0u);
  CHECK(data.q[kHumanElbowYaw] == yaw_before);
  CHECK(std::abs(data.q[kHumanElbowRoll] - 1.0 * kDeg) < 1e-9);
  CHECK(data.q.allFinite());
}

TEST_CASE("missing or non-finite keypoints give a fault flag, never NaN and never a made-up point") {
  const tools::SynthDemo demo = tools::generateDemo(Movement::kElbow, 0, 6, true);
  const HumanKinematicsConfig config;
  struct Case {
    std::vector<int> missing;
    std::uint32_t flag;
  };
  const std::vector<Case> cases = {
      {{kRShoulder}, kHumanNoTorso | kHumanNoArm}, {{kLShoulder}, kHumanNoTorso},
      {{kMidHip, kRHip}, kHumanNoTorso},           {{kMidHip, kLHip}, kHumanNoTorso},
      {{kRElbow}, kHumanNoArm},                    {{kRWrist}, kHumanNoArm},
  };
  for (const Case& c : cases) {
    HumanArmData data;
    humanArmKinematics(config, data, demo.truth[50]);
    REQUIRE(data.valid);
    const HumanArmData before = data;
    SkeletonFrame f = demo.truth[60];
    for (int i : c.missing) {
      f.ok[i] = false;
      f.p_W[i].setConstant(std::numeric_limits<double>::quiet_NaN());  // a reader may leave garbage
    }
    humanArmKinematics(config, data, f);
    CHECK_FALSE(data.valid);
    CHECK_MESSAGE(data.flags == c.flag, "missing " << std::string(kSkeletonPointNames[c.missing[0]]) << ": expected flags " << c.flag
                                                   << ", got " << data.flags);
    CHECK(data.q == before.q);
    CHECK(data.p_SH_T == before.p_SH_T);
    CHECK(data.q.allFinite());
  }
  // A point marked valid but NaN.
  HumanArmData data;
  SkeletonFrame f = demo.truth[10];
  f.p_W[kRElbow].x() = std::numeric_limits<double>::quiet_NaN();
  humanArmKinematics(config, data, f);
  CHECK_FALSE(data.valid);
  CHECK((data.flags & kHumanNotFinite) != 0u);
  CHECK(data.q.allFinite());
  // Degenerate: elbow on the shoulder.
  f = demo.truth[10];
  f.p_W[kRElbow] = f.p_W[kRShoulder];
  humanArmKinematics(config, data, f);
  CHECK_FALSE(data.valid);
  CHECK((data.flags & kHumanNoArm) != 0u);
  // MidHip missing alone: the hips' mean stands in.
  f = demo.truth[10];
  f.ok[kMidHip] = false;
  humanArmKinematics(config, data, f);
  CHECK(data.valid);
  CHECK(angleDiff(data.q[kHumanShoulderPitch], demo.q[10][kHumanShoulderPitch]) < 1e-9);
}

TEST_CASE("ElbowYaw stays continuous when the forearm wobbles across the atan2 cut at +-pi") {
  // Upper arm hanging (ShoulderPitch pi/2), elbow at 90 deg, forearm pointing straight out to
  // the right (-y): ElbowYaw is +-pi, and a 1 deg wobble of the forearm crosses the cut.
  SkeletonFrame f;
  const Eigen::Vector3d p_WRS(0.0, -0.2, 1.4), p_WLS(0.0, 0.2, 1.4);
  auto place = [&](int i, const Eigen::Vector3d& p) {
    f.p_W[i] = p;
    f.ok[i] = true;
  };
  place(kRShoulder, p_WRS);
  place(kLShoulder, p_WLS);
  place(kMidHip, Eigen::Vector3d(0.0, 0.0, 0.9));
  const Eigen::Vector3d p_WE = p_WRS + Eigen::Vector3d(0.0, 0.0, -0.3);
  place(kRElbow, p_WE);
  HumanKinematicsConfig config;
  HumanArmData data;
  resetHumanArm(data);
  double previous = 0.0, largest_step = 0.0;
  for (int k = 0; k < 20; ++k) {
    const double eps = (k % 2 == 0 ? 1.0 : -1.0) * kDeg;
    place(kRWrist, p_WE + 0.25 * Eigen::Vector3d(std::sin(eps), -std::cos(eps), 0.0));
    humanArmKinematics(config, data, f);
    REQUIRE(data.valid);
    const double yaw = data.q[kHumanElbowYaw];
    const bool on_branch = std::abs(std::abs(yaw) - (3.14159265358979323846 - 1.0 * kDeg)) < 1e-6 ||
                           std::abs(std::abs(yaw) - (3.14159265358979323846 + 1.0 * kDeg)) < 1e-6;
    CHECK_MESSAGE(on_branch, "frame " << k << ": ElbowYaw " << yaw << " is not pi -+ 1 deg");
    if (k > 0) largest_step = std::max(largest_step, std::abs(yaw - previous));
    previous = yaw;
  }
  // A 2 deg wobble, not a 2 pi jump.
  CHECK_MESSAGE(largest_step < 2.5 * kDeg, "ElbowYaw jumped by " << largest_step << " rad between frames");
}

namespace {

// A right arm in the torso frame of poseFrame's body (identity torso at p_WT): the upper arm
// along `u`, the forearm along `f`, the hand's x axis along the forearm and its palm normal as
// near `palm` as the hand axis allows. Points only: no joint convention involved.
SkeletonFrame directionFrame(const tools::Anthropometrics& body, const Eigen::Vector3d& p_WT, const Eigen::Vector3d& u,
                             const Eigen::Vector3d& f, const Eigen::Vector3d& palm) {
  SkeletonFrame frame = poseFrame(body, Eigen::Matrix3d::Identity(), p_WT, HumanJointVector::Zero());
  const Eigen::Vector3d p_WS = frame.p_W[kRShoulder];
  const Eigen::Vector3d p_WE = p_WS + body.upper_arm_m * u.normalized();
  const Eigen::Vector3d p_WR = p_WE + body.forearm_m * f.normalized();
  Eigen::Matrix3d R_WK;
  R_WK.col(0) = f.normalized();
  R_WK.col(1) = (palm - R_WK.col(0) * R_WK.col(0).dot(palm)).normalized();
  R_WK.col(2) = R_WK.col(0).cross(R_WK.col(1));
  frame.p_W[kRElbow] = p_WE;
  frame.p_W[kRWrist] = p_WR;
  for (int h = 0; h < 4; ++h) frame.p_W[kRHand0 + h] = p_WR + R_WK * body.p_KHand[static_cast<std::size_t>(h)];
  return frame;
}

}  // namespace

TEST_CASE("a lateral raise through the horizontal, 20 times up and down: exact angles 15 deg or more from the shoulder's pole, no whole-turn drift of ElbowYaw or WristYaw") {
  // The arm, slightly bent and palm down, swings up sideways from 70 to 110 deg of elevation in
  // five frames and back, in the frontal plane turned 2 deg forward: it passes 2 deg from the
  // pole where ShoulderPitch is undefined. Away from the pole the angles must be the exact
  // (first-measurement) ones; through it ShoulderPitch turns by ~pi through the front and
  // ElbowYaw with it, and after 20 passes neither twist has gathered a turn.
  const tools::Anthropometrics body = tools::generateDemo(Movement::kWholeArm, 0, 1, true).body;
  const HumanKinematicsConfig config;
  const Eigen::Vector3d p_WT(0.0, 0.0, 1.4);
  const double plane = 2.0 * kDeg, bend = 12.0 * kDeg;
  auto frameAt = [&](double elevation) {
    const Eigen::Vector3d axis(std::cos(plane), std::sin(plane), 0.0);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(-elevation, axis).toRotationMatrix();
    const Eigen::Vector3d f0 = -std::cos(bend) * Eigen::Vector3d::UnitZ() + std::sin(bend) * Eigen::Vector3d::UnitX();
    return directionFrame(body, p_WT, R * -Eigen::Vector3d::UnitZ(), R * f0, R * Eigen::Vector3d::UnitY());
  };
  HumanArmData data;
  resetHumanArm(data);
  double largest_twist = 0.0, worst_exact = 0.0;
  int n_exact = 0;
  for (int pass = 0; pass < 20; ++pass) {
    for (int k = 0; k <= 10; ++k) {
      const double elevation = (70.0 + 40.0 * (k <= 5 ? k : 10 - k) / 5.0) * kDeg;
      const SkeletonFrame f = frameAt(elevation);
      humanArmKinematics(config, data, f);
      REQUIRE(data.valid);
      REQUIRE(data.q.allFinite());
      largest_twist = std::max({largest_twist, std::abs(data.q[kHumanElbowYaw]), std::abs(data.q[kHumanWristYaw])});
      if (std::cos(data.q[kHumanShoulderRoll]) >= config.shoulder_exact_cos) {
        HumanArmData fresh;
        humanArmKinematics(config, fresh, f);
        for (int j = 0; j < kNumHumanJoints; ++j) worst_exact = std::max(worst_exact, angleDiff(data.q[j], fresh.q[j]));
        ++n_exact;
      }
    }
  }
  MESSAGE(n_exact << " frames 15 deg or more from the pole, largest difference from the exact angles " << worst_exact
                  << " rad; largest |ElbowYaw|, |WristYaw| " << largest_twist << " rad");
  REQUIRE(n_exact >= 20 * 3);  // 70 deg up, 110 deg at the top, 70 deg down
  CHECK_MESSAGE(worst_exact < 1e-9, "away from the pole the angles should be the exact ones (mod 2 pi), off by " << worst_exact);
  CHECK_MESSAGE(largest_twist < 1.5 * kPi, "a twist drifted to " << largest_twist << " rad over 20 passes");
}

TEST_CASE("near a straight elbow ElbowYaw follows only part of a measured swing, and the forearm's total twist stays with WristYaw") {
  // A forearm 4 deg from straight (between the 3 deg hold and the 6 deg of exactness): a 1 rad
  // turn of the forearm about the upper arm moves ElbowYaw by sin(4)/sin(6) of it, and WristYaw
  // takes the rest, so ElbowYaw + WristYaw (the twist of the nearly straight arm) follows the hand.
  const tools::Anthropometrics body = tools::generateDemo(Movement::kWholeArm, 0, 1, true).body;
  const HumanKinematicsConfig config;
  const Eigen::Vector3d p_WT(0.0, 0.0, 1.4);
  HumanJointVector q;
  q << 30 * kDeg, -20 * kDeg, 40 * kDeg, 4 * kDeg, -30 * kDeg, 0.0, 0.0;
  HumanArmData data;
  humanArmKinematics(config, data, poseFrame(body, Eigen::Matrix3d::Identity(), p_WT, q));
  REQUIRE(data.flags == 0u);
  const HumanJointVector before = data.q;
  HumanJointVector q2 = q;
  q2[kHumanElbowYaw] += 1.0;
  q2[kHumanWristYaw] -= 0.3;
  humanArmKinematics(config, data, poseFrame(body, Eigen::Matrix3d::Identity(), p_WT, q2));
  REQUIRE(data.valid);
  CHECK((data.flags & kHumanNearPole) != 0u);
  const double share = std::sin(4 * kDeg) / std::sin(6 * kDeg);
  CHECK(std::abs((data.q[kHumanElbowYaw] - before[kHumanElbowYaw]) - share * 1.0) < 1e-9);
  const double twist_before = before[kHumanElbowYaw] + before[kHumanWristYaw];
  const double twist_after = data.q[kHumanElbowYaw] + data.q[kHumanWristYaw];
  // cos(4 deg) of the ElbowYaw change shows in the forearm's own twist.
  CHECK_MESSAGE(std::abs((twist_after - twist_before) - (1.0 - 0.3)) < 0.02,
                "expected the total twist to move by 0.7 rad, it moved by " << twist_after - twist_before);
  CHECK(std::abs(data.q[kHumanElbowRoll] - 4 * kDeg) < 1e-9);
}
