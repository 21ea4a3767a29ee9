// The synthesiser's camera model (docs/synth.md "Cameras"): one lab camera's intrinsics, drawn
// in a fixed order so that a seed gives the same rig whichever scene uses it.
#pragma once

#include "nao/tools/camera.hpp"
#include "synth_random.hpp"

#include <string>

namespace nao::tools {

/// Camera `index` of a rig: 1920 x 1080 px, f 1050-1150 px, fy/fx within +-0.2 %, principal point
/// within +-8 px of the centre, lens distortion k1 -0.12..-0.05, k2 0..0.08, |p1|, |p2| <= 5e-4.
/// The pose (R_CW, p_CW) is left to the caller.
inline Camera sampleLabIntrinsics(int index, SynthRandom& rng) {
  Camera c;
  c.name = "cam" + std::to_string(index);
  c.width = 1920;
  c.height = 1080;
  const double f = rng.uniform(1050.0, 1150.0);
  c.K << f, 0.0, 960.0 + rng.uniform(-8.0, 8.0), 0.0, f * (1.0 + rng.uniform(-0.002, 0.002)),
      540.0 + rng.uniform(-8.0, 8.0), 0.0, 0.0, 1.0;
  c.dist << rng.uniform(-0.12, -0.05), rng.uniform(0.0, 0.08), rng.uniform(-5e-4, 5e-4), rng.uniform(-5e-4, 5e-4), 0.0;
  return c;
}

}  // namespace nao::tools
