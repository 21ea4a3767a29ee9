// Helpers shared by the tests: the project's URDF, seeded random poses, temporary files.
#pragma once

#include "nao/arm_model.hpp"
#include "nao/arm_model_io.hpp"

#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

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

/// The columns of a CSV file with a header row (e.g. nao_rt's ticks.csv) by name, one number
/// per row (strtod: "nan" reads as NaN); empty if the file cannot be read.
inline std::map<std::string, std::vector<double>> readCsvColumns(const std::filesystem::path& file) {
  std::ifstream csv(file);
  std::string line;
  std::map<std::string, std::vector<double>> columns;
  if (!std::getline(csv, line)) return columns;
  std::vector<std::string> names;
  std::stringstream header(line);
  for (std::string name; std::getline(header, name, ',');) names.push_back(name);
  for (const std::string& name : names) columns[name];
  while (std::getline(csv, line)) {
    std::stringstream row(line);
    std::string cell;
    for (std::size_t i = 0; i < names.size() && std::getline(row, cell, ','); ++i)
      columns[names[i]].push_back(std::strtod(cell.c_str(), nullptr));
  }
  return columns;
}

inline constexpr double kDeg = 3.14159265358979323846 / 180.0;

}  // namespace nao::test
