// Recorded references for the tests that run nao_rt in process or as a binary: a held-out
// synthetic demonstration (demonstration 0 of run seed 1000000 + seed, as toolchain/nao demo
// synthesises it) as the two cameras and the triangulation see it, written as the 10 Hz skeleton
// CSV nao_rt reads (--reference file:PATH), exactly (17 digits: the run on the file is the run on
// the frames, bit for bit).
#pragma once

#include "nao/skeleton_csv.hpp"
#include "nao/tools/reference_source.hpp"
#include "nao/tools/synth.hpp"

#include <cstdint>
#include <filesystem>
#include <string>

namespace nao::test {

/// DIR/<movement>_<seed>.csv, written once (reused when it exists).
inline std::string syntheticReferenceCsv(const std::string& movement, std::uint64_t seed,
                                         const std::filesystem::path& dir) {
  const std::filesystem::path path = dir / (movement + "_" + std::to_string(seed) + ".csv");
  if (!std::filesystem::exists(path)) {
    std::filesystem::create_directories(dir);
    const tools::SynthDemo demo =
        tools::generateDemo(tools::parseMovement(movement), 0, tools::kReferenceSeedBase + seed, false);
    writeSkeletonCsv(path.string(), tools::observeDemo(demo), false, 17);
  }
  return path.string();
}

}  // namespace nao::test
