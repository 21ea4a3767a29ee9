// Helpers shared by the tests: the project's URDF, seeded random poses, temporary files.
#pragma once

#include "nao/arm_model.hpp"

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

namespace nao::test {

inline const std::string kUrdfPath = NAO_DEFAULT_URDF;

inline std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

/// Writes `text` to a fresh file under the system temp directory and returns its path.
inline std::string writeTempFile(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / "nao_rt_tests";
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::ofstream(path) << text;
  return path.string();
}

/// Uniformly random pose inside the position limits, from a caller-owned seeded generator.
inline JointVector randomPose(const ArmModel& model, std::mt19937_64& rng) {
  JointVector q;
  for (int j = 0; j < kNumJoints; ++j) q[j] = std::uniform_real_distribution<double>(model.q_min[j], model.q_max[j])(rng);
  return q;
}

inline constexpr double kDeg = 3.14159265358979323846 / 180.0;

}  // namespace nao::test
