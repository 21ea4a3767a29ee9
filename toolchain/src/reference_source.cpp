#include "nao/tools/reference_source.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/human_scale.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/triangulate.hpp"

#include <algorithm>
#include <cmath>

namespace nao::tools {
namespace {

// Hand keypoints of OpenPose's 21-point hand that the skeleton keeps (docs/formats.md).
constexpr std::array<int, 4> kHandIds = {0, 5, 9, 17};

// One rendered camera frame as the OpenPose reader would have produced it from the file
// (0,0,0 = not detected; confidences clamped to 1 like the reader does).
Person2d toPerson(const OpenPoseFrame& f) {
  Person2d p;
  p.person_id = 0;
  auto put = [&p](int i, const Eigen::Vector3d& v) {
    if (v.z() <= 0.0) return;
    p.px[static_cast<std::size_t>(i)] = v.head<2>();
    p.confidence[static_cast<std::size_t>(i)] = std::min(v.z(), 1.0);
  };
  for (int k = 0; k < kNumBody25; ++k) put(k, f.pose[static_cast<std::size_t>(k)]);
  for (int h = 0; h < 4; ++h) put(kRHand0 + h, f.hand_right[static_cast<std::size_t>(kHandIds[static_cast<std::size_t>(h)])]);
  return p;
}

}  // namespace

void prepareReference(const ArmModel& arm, ReferenceStream& s, const std::vector<JointVector>& centroids,
                      const RetargetParams& retarget) {
  if (s.frames.empty()) throw UserError(s.description + ": no frames");
  if (centroids.empty()) throw UserError(s.description + ": the model has no key poses for " + s.movement);
  // Only frames the controller will see count (a missing tick is a missing human).
  Skeleton seen = s.frames;
  for (std::size_t i = 0; i < seen.size(); ++i)
    if (!s.present[i]) seen[i].ok.fill(false);
  RetargetOptions options;
  options.use_ceres = false;  // the runtime's own LM: the online and offline references agree
  options.params = retarget;
  const HumanArmLengths lengths = estimateHumanArmLengths(seen, options.human);
  if (lengths.n_arm_frames == 0) throw UserError(s.description + ": no frame has a measurable right arm");
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

ReferenceStream makeSyntheticReference(const ArmModel& arm, Movement movement, std::uint64_t seed, int index,
                                       const std::vector<JointVector>& centroids, const RetargetParams& retarget) {
  return makeDemoReference(arm, movement, kReferenceSeedBase + seed, index, centroids, retarget);
}

Skeleton observeDemo(const SynthDemo& demo, double rate_hz) {
  std::vector<CameraKeypoints> cams(demo.cameras.size());
  for (std::size_t c = 0; c < demo.cameras.size(); ++c) {
    const std::vector<OpenPoseFrame> rendered = renderCamera(demo, static_cast<int>(c));
    cams[c].dir = "cam" + std::to_string(c);
    cams[c].frames.resize(rendered.size());
    for (std::size_t k = 0; k < rendered.size(); ++k) {
      cams[c].frames[k].index = static_cast<long long>(k);
      cams[c].frames[k].people.push_back(toPerson(rendered[k]));
    }
  }
  TriangulateOptions opt;
  opt.fps = demo.fps;
  opt.rate_hz = rate_hz;
  // The reference stands for a live detector: nothing after a frame may fill it, so no offline
  // gap interpolation (nao_rt bridges short gaps itself, causally).
  opt.max_gap_s = 0.0;
  return resampleSkeleton(triangulateCapture(demo.cameras, cams, opt), opt.rate_hz, demo.fps);
}

ReferenceStream makeDemoReference(const ArmModel& arm, Movement movement, std::uint64_t run_seed, int index,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget) {
  const SynthDemo demo = generateDemo(movement, index, run_seed, false);
  ReferenceStream s;
  s.movement = kMovementNames[static_cast<std::size_t>(movement)];
  s.description = "synthetic:" + s.movement + " (seed " + std::to_string(run_seed) + ", index " +
                  std::to_string(index) + ")";
  s.frames = observeDemo(demo, s.rate_hz);
  s.present.assign(s.frames.size(), true);
  prepareReference(arm, s, centroids, retarget);
  return s;
}

ReferenceStream makeFileReference(const ArmModel& arm, const std::string& path, const std::string& movement,
                                  const std::vector<JointVector>& centroids, const RetargetParams& retarget) {
  ReferenceStream s;
  s.movement = movement;
  s.description = "file:" + path;
  s.frames = readSkeletonCsv(path);
  if (s.frames.size() < 2) throw UserError(path + ": fewer than two samples");
  for (std::size_t i = 1; i < s.frames.size(); ++i) {
    const double dt = s.frames[i].t_s - s.frames[i - 1].t_s;
    if (std::abs(dt - 0.1) > 1e-6)
      throw UserError(path + ": samples " + std::to_string(i - 1) + " and " + std::to_string(i) + " are " +
                      std::to_string(dt) + " s apart; nao_rt needs a 10 Hz skeleton (triangulate --rate 10)");
  }
  s.present.assign(s.frames.size(), true);
  prepareReference(arm, s, centroids, retarget);
  return s;
}

}  // namespace nao::tools
