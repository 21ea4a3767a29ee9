// Calibrated pinhole camera with OpenCV's distortion model (k1, k2, p1, p2, k3), shared by the
// runtime's live camera source and the toolchain's offline triangulation.
//
// Frames (docs/notation.md): W the calibration's world frame, C the camera frame (x right,
// y down, z along the optical axis). p_C = R_CW p_W + p_CW.
#pragma once

#include <Eigen/Core>

#include <string>
#include <vector>

namespace nao {

struct Camera {
  std::string name;
  int width = 0, height = 0;                         ///< image size, px
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();   ///< intrinsics, px
  Eigen::Matrix<double, 5, 1> dist = Eigen::Matrix<double, 5, 1>::Zero();  ///< k1 k2 p1 p2 k3
  Eigen::Matrix3d R_CW = Eigen::Matrix3d::Identity();  ///< world -> camera rotation
  Eigen::Vector3d p_CW = Eigen::Vector3d::Zero();      ///< world origin in the camera frame, m
};

using CameraSet = std::vector<Camera>;

/// Point p_W (world frame, m) in camera frame C.
inline Eigen::Vector3d toCamera(const Camera& cam, const Eigen::Vector3d& p_W) { return cam.R_CW * p_W + cam.p_CW; }

/// Normalised image coordinates (x/z, y/z) -> distorted normalised coordinates (OpenCV model).
inline Eigen::Vector2d distort(const Camera& cam, const Eigen::Vector2d& xn) {
  const double k1 = cam.dist[0], k2 = cam.dist[1], p1 = cam.dist[2], p2 = cam.dist[3], k3 = cam.dist[4];
  const double x = xn.x(), y = xn.y(), r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
          y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
}

/// Pixel coordinates of p_W (world frame, m). The point must lie in front of the camera
/// (z_C > 0); callers check that with toCamera when it matters.
inline Eigen::Vector2d project(const Camera& cam, const Eigen::Vector3d& p_W) {
  const Eigen::Vector3d p_C = toCamera(cam, p_W);
  const Eigen::Vector2d xd = distort(cam, Eigen::Vector2d(p_C.x() / p_C.z(), p_C.y() / p_C.z()));
  return {cam.K(0, 0) * xd.x() + cam.K(0, 1) * xd.y() + cam.K(0, 2), cam.K(1, 1) * xd.y() + cam.K(1, 2)};
}

/// Rotation matrix of a Rodrigues (axis * angle) vector, rad.
Eigen::Matrix3d rotationFromRodrigues(const Eigen::Vector3d& r);

/// Rodrigues vector of a rotation matrix (angle in [0, pi]).
Eigen::Vector3d rodriguesFromRotation(const Eigen::Matrix3d& R);

}  // namespace nao
