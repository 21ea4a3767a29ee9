// The embodiment gap on held-out synthetic demonstrations (seed 424242; the training set is
// seed 1): the human side carries it (each movement's hand path is drawn by the DoF it is
// about), and the imitation reference q_r bridges it where the clamped human angles do not.
#include "nao/tools/embodiment_gap.hpp"
#include "nao/tools/reference_source.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <iomanip>

using namespace nao;
using namespace nao::tools;

namespace {

constexpr std::uint64_t kHeldOutSeed = 424242;

const ArmModel& arm() {
  static const ArmModel model = loadArmModel(nao::test::kUrdfPath);
  return model;
}

}  // namespace

TEST_CASE("each movement's hand path is drawn mainly by the human DoFs it is about (6 demos each)") {
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    HandPathShares mean;
    constexpr int kDemos = 6;
    for (int i = 0; i < kDemos; ++i) {
      const HandPathShares s = handPathShares(generateDemo(m, i, kHeldOutSeed, false));
      double sum = 0.0;
      for (double x : s.dof) sum += x;
      CHECK(std::abs(sum - 1.0) < 1e-9);
      for (int k = 0; k < kNumHumanJoints; ++k) mean.dof[static_cast<std::size_t>(k)] += s.dof[static_cast<std::size_t>(k)] / kDemos;
      mean.shoulder += s.shoulder / kDemos;
      mean.elbow += s.elbow / kDemos;
      mean.forearm += s.forearm / kDemos;
      mean.wrist += s.wrist / kDemos;
      mean.spread_rms_m += s.spread_rms_m / kDemos;
    }
    const std::string name = kMovementNames[static_cast<std::size_t>(m)];
    std::ostringstream dofs;
    for (int k = 0; k < kNumHumanJoints; ++k) dofs << ' ' << kHumanJointNames[k] << ' ' << std::setprecision(2) << mean.dof[static_cast<std::size_t>(k)];
    MESSAGE(name << ": shoulder " << mean.shoulder << ", elbow " << mean.elbow << ", forearm " << mean.forearm
                 << ", wrist (NAO lacks) " << mean.wrist << "; hand spread " << mean.spread_rms_m * 100 << " cm RMS;"
                 << dofs.str());
    const double main_share = m == Movement::kWholeArm ? mean.shoulder : m == Movement::kElbow ? mean.elbow : mean.wrist;
    CHECK_MESSAGE(main_share > 0.6, name << ": expected its own DoF group to draw > 60 % of the hand-path spread, got "
                                         << main_share);
  }
}

TEST_CASE("q_r bridges the embodiment gap on held-out demonstrations: hand on target, inside the limits, the gap reported") {
  RetargetOptions options;
  options.use_ceres = false;  // the runtime's solver; test_retarget_dataset ties it to Ceres
  for (Movement m : {Movement::kWholeArm, Movement::kElbow, Movement::kWrist}) {
    std::vector<std::vector<GapFrame>> sequences;
    for (int i = 0; i < 4; ++i) {
      const SynthDemo demo = generateDemo(m, i, kHeldOutSeed, false);
      sequences.push_back(embodimentGap(arm(), retargetSkeleton(arm(), observeDemo(demo), options)));
    }
    const GapSummary g = summariseGap(sequences);
    const std::string name = kMovementNames[static_cast<std::size_t>(m)];
    MESSAGE(name << ": " << g.frames << " frames; median hand miss: clamped human angles " << g.median_clamp_miss_m * 1e3
                 << " mm, q_r " << g.median_r_miss_m * 1e3 << " mm (" << 100 * g.frac_r_within_1cm
                 << " % within 1 cm; " << g.unreachable << " frames out of NAO's reach, " << 100 * g.frac_r_within_1cm_reachable
                 << " % of the reachable ones within 1 cm); median |q_r - clamp| " << g.median_dq_rad << " rad (per joint "
                 << g.median_abs_dq_joint[0] << " " << g.median_abs_dq_joint[1] << " " << g.median_abs_dq_joint[2] << " "
                 << g.median_abs_dq_joint[3] << " " << g.median_abs_dq_joint[4] << "); shoulder+elbow speed RMS q_r / clamp "
                 << g.speed_ratio_shoulder_elbow << "; clamp misses > 1 cm on " << g.clamp_miss_frames << " frames, q_r within 1 cm on "
                 << 100 * g.frac_recovered << " % of them; " << g.fallbacks << " fallbacks");
    REQUIRE(g.frames > 200);
    CHECK_MESSAGE(g.frac_r_within_1cm_reachable >= 0.95, name << ": q_r within 1 cm on " << 100 * g.frac_r_within_1cm_reachable
                                                               << " % of the frames NAO can reach");
    CHECK_MESSAGE(g.median_r_miss_m <= 2e-3, name << ": median q_r hand miss " << g.median_r_miss_m * 1e3 << " mm");
    CHECK_MESSAGE(g.outside_limits == 0, name << ": " << g.outside_limits << " frames with q_r outside the limits");
    // q_r must do better than the naive mapping it replaces.
    CHECK_MESSAGE(g.median_r_miss_m < 0.5 * g.median_clamp_miss_m, name << ": q_r does not beat the clamp");
    if (m == Movement::kWrist) {
      CHECK_MESSAGE(g.median_dq_rad >= 0.03, "wrist: expected q_r to depart from the clamped angles by a median >= 0.03 rad, got "
                                                 << g.median_dq_rad);
      CHECK_MESSAGE(g.frac_recovered >= 0.95, "wrist: q_r reaches only " << 100 * g.frac_recovered
                                                                         << " % of the targets the clamp misses by > 1 cm");
    }
  }
}
