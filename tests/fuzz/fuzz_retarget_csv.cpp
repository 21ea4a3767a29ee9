// Fuzz target: retarget CSV (readRetargetCsv, what cluster reads; through a scratch file).
// Either rows of finite numbers with one retargeting setting, or UserError.
#include "fuzz_util.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/retarget_pipeline.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = nao::fuzz::writeScratch("retarget.csv", data, size);
  try {
    nao::RetargetParams setting;
    const std::vector<nao::tools::RetargetRow> rows = nao::tools::readRetargetCsv(path, &setting);
    for (const nao::tools::RetargetRow& r : rows) {
      NAO_FUZZ_CHECK(r.result.q_x.allFinite() && r.result.q_q.allFinite() && r.result.q_r.allFinite());
      NAO_FUZZ_CHECK(r.target.p_target_TH.allFinite() && r.target.q_target.allFinite());
      NAO_FUZZ_CHECK((r.result.flags & ~0xffu) == 0);
    }
  } catch (const nao::tools::UserError&) {
  }
  return 0;
}
