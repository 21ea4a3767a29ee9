// Fuzz target: skeleton CSV (readSkeletonCsv, through a scratch file: the reader takes a
// path). Either frames with increasing finite times and finite points, or UserError.
#include "fuzz_util.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/skeleton_csv.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = nao::fuzz::writeScratch("skeleton.csv", data, size);
  try {
    const nao::tools::Skeleton frames = nao::tools::readSkeletonCsv(path);
    for (std::size_t f = 0; f < frames.size(); ++f) {
      NAO_FUZZ_CHECK(std::isfinite(frames[f].t_s));
      NAO_FUZZ_CHECK(f == 0 || frames[f].t_s > frames[f - 1].t_s);
      for (int i = 0; i < nao::kNumSkeletonPoints; ++i) NAO_FUZZ_CHECK(frames[f].p_W[i].allFinite());
    }
  } catch (const nao::tools::UserError&) {
  }
  return 0;
}
