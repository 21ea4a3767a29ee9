// Retargeting over the whole synthetic data set: the runtime's fixed-size LM against the offline
// Ceres version on every 10 Hz frame of all 240 demonstrations (the synthesiser's ground-truth
// skeletons, so the comparison is about the solvers, not the triangulation). q_x (the default
// q_r) is where the solvers could part: the posture price makes the objective non-convex, and
// where two local minima are near-equal the 1e-8 differences of two solvers can pick different
// ones (and the warm start carries the choice on for a few frames). Such frames are counted.
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/synth.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>

using namespace nao;
using namespace nao::tools;

TEST_CASE("on >= 99 % of the 10 Hz frames of the 240-demonstration set the fixed-size LM and Ceres find the same q_x and q_q within 1e-4 rad, all inside the limits") {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  RetargetOptions options;
  double worst_x = 0.0, worst_q = 0.0;
  int n_frames = 0, n_outside = 0, n_agree_x = 0, n_agree_q = 0;
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
      for (std::size_t i = 0; i < lm.size(); ++i) {
        n_agree_x += (lm[i].q_x - ceres[i].q_x).cwiseAbs().maxCoeff() < 1e-4;
        n_agree_q += (lm[i].q_q - ceres[i].q_q).cwiseAbs().maxCoeff() < 1e-4;
      }
      worst_x = std::max(worst_x, a.max_abs_q_x);
      worst_q = std::max(worst_q, a.max_abs_q_q);
      for (const std::vector<RetargetResult>* run : {&lm, &ceres})
        for (const RetargetResult& r : *run)
          for (const JointVector* q : {&r.q_x, &r.q_q})
            n_outside += ((q->array() < arm.q_min.array()) || (q->array() > arm.q_max.array())).any();
      n_frames += static_cast<int>(frames.size());
    }
  }
  const double share_x = static_cast<double>(n_agree_x) / n_frames, share_q = static_cast<double>(n_agree_q) / n_frames;
  MESSAGE(n_frames << " frames: within 1e-4 rad q_x " << 100.0 * share_x << " %, q_q " << 100.0 * share_q
                   << " %; largest LM-Ceres difference q_x " << worst_x << " rad, q_q " << worst_q << " rad ("
                   << worst_demo << ")");
  CHECK(n_frames > 30000);
  CHECK_MESSAGE(share_x >= 0.99, "q_x agrees within 1e-4 rad on only " << 100.0 * share_x << " % of frames");
  CHECK_MESSAGE(share_q >= 0.99, "q_q agrees within 1e-4 rad on only " << 100.0 * share_q << " % of frames");
  CHECK_MESSAGE(n_outside == 0, n_outside << " poses outside the URDF limits");
}
