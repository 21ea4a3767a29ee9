// Synthetic two-to-four-camera scenes with known 3D truth for the triangulation suites
// (test_triangulate.cpp, test_triangulate_stress.cpp): a standing adult moving its right arm,
// seen through cameras with mild lens distortion, and what each camera detects of it.
#pragma once

#include "nao/body25.hpp"
#include "nao/camera.hpp"
#include "nao/openpose_json.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

namespace nao::test {

using Points = std::array<Eigen::Vector3d, kNumSkeletonPoints>;
using FramePeople = std::vector<std::vector<Person2d>>;  // [camera][person]

inline Camera lookAt(const std::string& name, const Eigen::Vector3d& C_W, const Eigen::Vector3d& target_W, double f,
              const Eigen::Matrix<double, 5, 1>& dist) {
  Camera cam;
  cam.name = name;
  cam.width = 1920, cam.height = 1080;
  cam.K << f, 0.0, 962.0, 0.0, f * 1.001, 541.0, 0.0, 0.0, 1.0;
  cam.dist = dist;
  const Eigen::Vector3d z = (target_W - C_W).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();  // image right
  const Eigen::Vector3d y = z.cross(x);                                      // image down
  cam.R_CW.row(0) = x.transpose(), cam.R_CW.row(1) = y.transpose(), cam.R_CW.row(2) = z.transpose();
  cam.p_CW = -cam.R_CW * C_W;
  return cam;
}

// Two cameras in front of the subject at shoulder height, left and right; optionally a third
// one higher up. All with mild, different lens distortion.
inline CameraSet cameras(int n) {
  Eigen::Matrix<double, 5, 1> d0, d1, d2;
  d0 << -0.04, 0.01, 0.0004, -0.0002, 0.0;
  d1 << 0.03, -0.008, -0.0003, 0.0001, 0.001;
  d2 << -0.02, 0.0, 0.0, 0.0003, 0.0;
  const Eigen::Vector3d target(0.0, 0.0, 1.0);
  CameraSet cams = {lookAt("cam0", {3.0, -1.3, 1.4}, target, 900.0, d0), lookAt("cam1", {3.0, 1.3, 1.4}, target, 910.0, d1)};
  if (n == 3) cams.push_back(lookAt("cam2", {2.6, 0.3, 2.3}, target, 890.0, d2));
  return cams;
}

// A standing adult (world: z up, facing +x, left = +y), metres, moving its right arm with t.
// MidHip sits 1 cm above the hips' mean on purpose (BODY_25B must use the mean, not MidHip).
inline Points body(double t, const Eigen::Vector3d& offset = Eigen::Vector3d::Zero()) {
  Points p;
  auto put = [&](int i, double x, double y, double z) { p[static_cast<std::size_t>(i)] = offset + Eigen::Vector3d(x, y, z); };
  put(kNose, 0.10, 0.0, 1.62), put(kNeck, 0.0, 0.0, 1.47), put(kRShoulder, 0.0, -0.19, 1.44);
  put(kLShoulder, 0.0, 0.19, 1.44), put(kLElbow, 0.02, 0.23, 1.16), put(kLWrist, 0.08, 0.25, 0.91);
  put(kMidHip, 0.0, 0.0, 0.98), put(kRHip, 0.0, -0.10, 0.97), put(kLHip, 0.0, 0.10, 0.97);
  put(kRKnee, 0.03, -0.10, 0.53), put(kRAnkle, 0.0, -0.10, 0.09), put(kLKnee, 0.03, 0.10, 0.53);
  put(kLAnkle, 0.0, 0.10, 0.09), put(kREye, 0.09, -0.035, 1.66), put(kLEye, 0.09, 0.035, 1.66);
  put(kREar, 0.02, -0.075, 1.63), put(kLEar, 0.02, 0.075, 1.63), put(kLBigToe, 0.17, 0.12, 0.02);
  put(kLSmallToe, 0.15, 0.16, 0.02), put(kLHeel, -0.04, 0.10, 0.03), put(kRBigToe, 0.17, -0.12, 0.02);
  put(kRSmallToe, 0.15, -0.16, 0.02), put(kRHeel, -0.04, -0.10, 0.03);
  const double elevation = 0.5 + 0.6 * std::sin(1.3 * t), flexion = 0.7 + 0.4 * std::cos(0.9 * t);
  const Eigen::Vector3d upper = Eigen::Vector3d(std::sin(elevation), -0.15, -std::cos(elevation)).normalized();
  const Eigen::Vector3d fore =
      Eigen::Vector3d(std::sin(elevation + flexion), -0.05, -std::cos(elevation + flexion)).normalized();
  const Eigen::Vector3d side = fore.cross(Eigen::Vector3d::UnitY()).normalized();
  p[kRElbow] = p[kRShoulder] + 0.29 * upper;
  p[kRWrist] = p[kRElbow] + 0.25 * fore;
  p[kRHand0] = p[kRWrist] + 0.01 * fore;
  p[kRHand5] = p[kRWrist] + 0.09 * fore + 0.03 * side;
  p[kRHand9] = p[kRWrist] + 0.095 * fore + 0.005 * side;
  p[kRHand17] = p[kRWrist] + 0.08 * fore - 0.035 * side;
  return p;
}

inline double confidenceOf(int point, int frame, int camera) {
  const double u = 0.37 * point + 0.23 * frame + 0.11 * camera;
  return 0.55 + 0.4 * (u - std::floor(u));
}

// What camera `cam` sees of `points`: points outside the image are not detected.
inline Person2d view(const Camera& cam, const Points& points, int frame, int camera, bool equal_confidence = false) {
  Person2d person;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    if (toCamera(cam, points[static_cast<std::size_t>(i)]).z() <= 0.0) continue;
    const Eigen::Vector2d px = project(cam, points[static_cast<std::size_t>(i)]);
    if (px.x() < 0.0 || px.y() < 0.0 || px.x() >= cam.width || px.y() >= cam.height) continue;
    person.px[i] = px;
    person.confidence[i] = equal_confidence ? 0.9 : confidenceOf(i, frame, camera);
  }
  return person;
}

struct Capture {
  CameraSet cams;
  std::vector<Points> truth;          // the subject, per frame
  std::vector<FramePeople> people;    // per frame
};

// The subject alone in every view, frames at 30 Hz.
inline Capture subjectOnly(int n_cameras, int n_frames, bool equal_confidence = false) {
  Capture c;
  c.cams = cameras(n_cameras);
  for (int k = 0; k < n_frames; ++k) {
    c.truth.push_back(body(k / 30.0, Eigen::Vector3d(0.0, 0.004 * k, 0.0)));
    FramePeople people(c.cams.size());
    for (std::size_t cam = 0; cam < c.cams.size(); ++cam)
      people[cam].push_back(view(c.cams[cam], c.truth.back(), k, static_cast<int>(cam), equal_confidence));
    c.people.push_back(people);
  }
  return c;
}

inline double error(const SkeletonFrame& f, const Points& truth, int i) {
  return (f.p_W[static_cast<std::size_t>(i)] - truth[static_cast<std::size_t>(i)]).norm();
}

inline double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

}  // namespace nao::test
