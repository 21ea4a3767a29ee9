// The recorded reference of a run (nao/reference_stream.hpp).
#include "nao/reference_stream.hpp"

#include "nao/feature_trajectory.hpp"
#include "nao/human_scale.hpp"
#include "nao/input_error.hpp"
#include "nao/retarget_sequence.hpp"

#include <cmath>
#include <string>

namespace nao {

void prepareReference(const ArmModel& arm, ReferenceStream& s, const std::vector<JointVector>& centroids,
                      const RetargetParams& retarget) {
  if (s.frames.empty()) throw InputError(s.description + ": no frames");
  if (centroids.empty()) throw InputError(s.description + ": the model has no key poses for " + s.movement);
  // Only frames the controller will see count (a missing tick is a missing human).
  Skeleton seen = s.frames;
  for (std::size_t i = 0; i < seen.size(); ++i)
    if (!s.present[i]) seen[i].ok.fill(false);
  RetargetOptions options;
  options.use_ceres = false;  // the runtime's own LM: the online and offline references agree
  options.params = retarget;
  const HumanArmLengths lengths = estimateHumanArmLengths(seen, options.human);
  if (lengths.n_arm_frames == 0) throw InputError(s.description + ": no frame has a measurable right arm");
  s.human = withDemoScale(options.human, lengths);
  const std::vector<RetargetRow> rows = retargetSkeletonLm(arm, seen, options);
  std::vector<double> t_meas, t_grid;
  std::vector<JointVector> q_meas;
  s.retargeted.clear();
  s.measured.clear();
  for (const RetargetRow& r : rows) {
    const bool measured = (r.flags & kRowHumanMissing) == 0;
    t_grid.push_back(r.t_s);
    s.retargeted.push_back(r.result.q_r);
    s.measured.push_back(measured);
    if (!measured) continue;
    t_meas.push_back(r.t_s);
    q_meas.push_back(r.result.q_r);
  }
  s.target = featureTrajectory(centroids, t_meas, q_meas, t_grid);
}

ReferenceStream makeFileReference(const ArmModel& arm, const std::string& path, const std::string& movement,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget) {
  ReferenceStream s;
  s.movement = movement;
  s.description = "file:" + path;
  s.frames = readSkeletonCsv(path);
  if (s.frames.size() < 2) throw InputError(path + ": fewer than two samples");
  for (std::size_t i = 1; i < s.frames.size(); ++i) {
    const double dt = s.frames[i].t_s - s.frames[i - 1].t_s;
    if (std::abs(dt - 0.1) > 1e-6)
      throw InputError(path + ": samples " + std::to_string(i - 1) + " and " + std::to_string(i) + " are " +
                      std::to_string(dt) + " s apart; nao_rt needs a 10 Hz skeleton (triangulate --rate 10)");
  }
  s.present.assign(s.frames.size(), true);
  prepareReference(arm, s, centroids, retarget);
  return s;
}

}  // namespace nao
