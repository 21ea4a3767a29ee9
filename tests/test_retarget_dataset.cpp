// Retargeting over the whole synthetic data set: the runtime's fixed-size LM against the offline
// Ceres version on every 10 Hz frame of all 240 demonstrations (the synthesiser's ground-truth
// skeletons, so the comparison is about the solvers, not the triangulation). q_x is where the
// solvers could part; q_q, anchored at the clamped joint target, is compared as well.
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/synth.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>

using namespace nao;
using namespace nao::tools;

TEST_CASE("on every 10 Hz frame of the 240-demonstration set the fixed-size LM and Ceres find the same q_x within 1e-4 rad, inside the limits") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  RetargetOptions options;
  double worst_x = 0.0, worst_q = 0.0;
  int n_frames = 0, n_outside = 0;
  std::string worst_demo;
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    for (int index = 0; index < 80; ++index) {
      const SynthDemo demo = generateDemo(m, index, 1, /*noise_free=*/true);
      Skeleton at_10hz;
      for (std::size_t f = 0; f < demo.truth.size(); f += 3) at_10hz.push_back(demo.truth[f]);
      std::vector<bool> ok, hand_seen;
      const std::vector<RetargetFrame> frames = retargetTargets(arm, at_10hz, options, ok, hand_seen);
      REQUIRE(std::count(ok.begin(), ok.end(), true) == static_cast<long>(ok.size()));
      const std::vector<RetargetResult> lm = retargetSequenceLM(arm, options.params, frames);
      const std::vector<RetargetResult> ceres = retargetSequenceCeres(arm, options.params, frames);
      const RetargetAgreement a = compareRetarget(lm, ceres);
      if (std::max(a.max_abs_q_x, a.max_abs_q_q) > std::max(worst_x, worst_q)) worst_demo = demo.name;
      worst_x = std::max(worst_x, a.max_abs_q_x);
      worst_q = std::max(worst_q, a.max_abs_q_q);
      for (const std::vector<RetargetResult>* run : {&lm, &ceres})
        for (const RetargetResult& r : *run)
          for (const JointVector* q : {&r.q_x, &r.q_q})
            n_outside += ((q->array() < arm.q_min.array()) || (q->array() > arm.q_max.array())).any();
      n_frames += static_cast<int>(frames.size());
    }
  }
  MESSAGE(n_frames << " frames: largest LM-Ceres difference q_x " << worst_x << " rad, q_q " << worst_q << " rad ("
                   << worst_demo << ")");
  CHECK(n_frames > 30000);
  CHECK_MESSAGE(worst_x < 1e-4, "q_x differs by " << worst_x << " rad in " << worst_demo);
  CHECK_MESSAGE(worst_q < 1e-4, "q_q differs by " << worst_q << " rad in " << worst_demo);
  CHECK_MESSAGE(n_outside == 0, n_outside << " poses outside the URDF limits");
}
