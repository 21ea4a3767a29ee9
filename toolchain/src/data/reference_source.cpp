#include "nao/tools/reference_source.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"
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

}  // namespace nao::tools
