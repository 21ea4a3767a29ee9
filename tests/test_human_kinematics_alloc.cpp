// Real-time property: the human kinematics allocate nothing per frame.
#include "nao/arm_model_io.hpp"
#include "nao/human_kinematics.hpp"
#include "nao/tools/synth.hpp"
#include "support/alloc_counter.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <vector>

using namespace nao;
using nao::test::CountAllocations;

TEST_CASE("10000 frames of human kinematics allocate nothing, including faulty frames") {
  // Frames prepared before counting: three movements, with missing hands, arms and torsos mixed in.
  std::vector<SkeletonFrame> frames;
  for (tools::Movement m : {tools::Movement::kWholeArm, tools::Movement::kElbow, tools::Movement::kWrist}) {
    const tools::SynthDemo demo = tools::generateDemo(m, 0, 13, false);
    frames.insert(frames.end(), demo.truth.begin(), demo.truth.end());
  }
  for (std::size_t k = 0; k < frames.size(); k += 5) frames[k].ok[kRHand5] = false;
  for (std::size_t k = 0; k < frames.size(); k += 11) frames[k].ok[kRElbow] = false;
  for (std::size_t k = 0; k < frames.size(); k += 13) frames[k].ok[kLShoulder] = false;
  const ArmModel arm = loadArmModel(NAO_DEFAULT_URDF);
  const double d_r = robotScale(arm);
  const HumanKinematicsConfig config;
  HumanArmData data;

  CountAllocations counter;
  double sink = 0.0;
  int n_valid = 0;
  for (int i = 0; i < 10000; ++i) {
    const HumanArmData& out = humanArmKinematics(config, data, frames[static_cast<std::size_t>(i) % frames.size()]);
    sink += out.q.sum();
    if (out.valid) sink += scaleHumanEndpoint(d_r, out.d_h_m, out.p_SH_T).x();  // NaN without a valid d_h
    n_valid += out.valid ? 1 : 0;
  }
  const std::int64_t n_alloc = counter.count();
  CHECK_MESSAGE(n_alloc == 0, "expected 0 heap allocations in 10000 frames, got " << n_alloc);
  CHECK(std::isfinite(sink));
  CHECK(n_valid > 5000);
  CHECK(n_valid < 10000);
}
