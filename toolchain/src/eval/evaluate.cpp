#include "nao/tools/evaluate.hpp"

#include "nao/kinematics.hpp"
#include "nao/model_file.hpp"
#include "nao/tools/synth.hpp"
#include "rt_metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao::tools {

HandPath handPath(const ArmModel& arm, const std::vector<JointVector>& q) {
  ArmData kin;
  HandPath path;
  path.reserve(q.size());
  for (const JointVector& v : q) path.push_back(forwardKinematics(arm, kin, v));
  return path;
}

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

NearestDemo nearestDemo(const HandPath& path, const std::vector<HandPath>& demos, int exclude) {
  NearestDemo best;
  best.dtw_m = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < demos.size(); ++i) {
    if (static_cast<int>(i) == exclude) continue;
    const double d = rt::dtwMeanDistance(path, demos[i]);
    if (best.index < 0 || d < best.dtw_m) {
      best.dtw_m = d;
      best.index = static_cast<int>(i);
    }
  }
  return best;
}

std::vector<std::vector<JointVector>> regenerateTargets(const ArmModel& arm, const std::string& movement,
                                                        std::uint64_t seed, const std::vector<int>& indices,
                                                        const std::vector<JointVector>& key_poses,
                                                        const RetargetParams& retarget) {
  const Movement m = parseMovement(movement);
  std::vector<std::vector<JointVector>> out;
  for (int index : indices) out.push_back(makeDemoReference(arm, m, seed, index, key_poses, retarget).target);
  return out;
}

}  // namespace nao::tools
