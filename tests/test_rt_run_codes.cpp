// nao_rt with a model's run codes (docs/autonomous.md): the code each autonomous run takes at
// activate, named in summary.json, and a malformed table refused at load. In process, a small
// random model loaded with --weights (support/rt_run_suite.hpp).
#include "nao/model_file.hpp"
#include "support/rt_run_suite.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <string>
#include <vector>

using namespace nao;
using namespace nao::test::rt_suite;

namespace {

// The elbow's two starts (whole_arm and wrist have none).
const JointVector kStartA = (JointVector() << 1.2, -0.3, 1.0, 0.6, 0.1).finished();
const JointVector kStartB = (JointVector() << 0.9, -0.5, 0.8, 0.9, -0.2).finished();

std::string startsMetadata() {
  const ModelStarts starts = {{{"elbow_003", 40, kStartA}, {"elbow_010", 25, kStartB}}, {}, {}};
  return withModelStarts("{}", {"elbow", "whole_arm", "wrist"}, starts);
}

}  // namespace

TEST_CASE("a model with run codes: each run takes the code of the medoid of the starts nearest its own, named in summary.json") {
  // Per movement 6 training demonstrations around the test starts, codes of the small d_model.
  const int d = smallArch().d_model;
  std::vector<ModelRunCodes> codes(3);
  for (std::size_t m = 0; m < 3; ++m) {
    ModelRunCodes& c = codes[m];
    c.d = d;
    for (int i = 0; i < 6; ++i) {
      c.names.push_back("train_" + std::to_string(m) + "_" + std::to_string(i));
      c.q.push_back(kStartB + JointVector::Constant(0.05 * (i - 2)) + JointVector(i % 2 ? JointVector(kStartA - kStartB) : JointVector::Zero()) * 0.5);
      for (int k = 0; k < d; ++k) c.code.push_back(0.4f * std::sin(0.7f * static_cast<float>(k + 3 * i + 11 * static_cast<int>(m))));
    }
    c.dtw_m.assign(36, 0.0);
    for (std::size_t i = 0; i < 6; ++i)
      for (std::size_t k = i + 1; k < 6; ++k) c.dtw_m[i * 6 + k] = c.dtw_m[k * 6 + i] = 0.001 * static_cast<double>((i * 7 + k * 3) % 11 + 1);
  }
  const std::string path = writeModel("autonomous_codes.bin", Conditioning::kAutonomous,
                                      withModelRunCodes(startsMetadata(), {"elbow", "whole_arm", "wrist"}, codes));
  const std::string plain = writeModel("autonomous_plain.bin", Conditioning::kAutonomous, startsMetadata());
  for (int start = 0; start < 2; ++start) {
    CAPTURE(start);
    const fs::path with_dir = tempDir("codes_" + std::to_string(start)), without_dir = tempDir("nocodes_" + std::to_string(start));
    const auto rollout = [&](const std::string& model, const fs::path& dir) {
      rt::RunOptions o = options(model, "none", dir);
      o.movement = "elbow";
      o.zero_timing = true;
      o.start_index = start;
      return o;
    };
    const rt::RunOptions with = rollout(path, with_dir), without = rollout(plain, without_dir);
    const Outcome rw = run(with), rn = run(without);
    REQUIRE_MESSAGE(rw.report.status == 0, rw.report.error);
    REQUIRE_MESSAGE(rn.report.status == 0, rn.report.error);
    const int expected = runCodeIndex(codes[0], start == 0 ? kStartA : kStartB);
    REQUIRE(expected >= 0);
    CHECK(nlohmann::json::parse(rw.report.summary_json)["run_code"] == codes[0].names[static_cast<std::size_t>(expected)]);
    CHECK(nlohmann::json::parse(rn.report.summary_json)["run_code"].is_null());
    CHECK(bytes(with_dir / "ticks.csv") != bytes(without_dir / "ticks.csv"));  // the code changes the run
  }
  // A malformed table is refused at load, naming the key.
  rt::RunOptions bad = options(writeModel("autonomous_badcodes.bin", Conditioning::kAutonomous,
                                          R"({"run_codes":{"elbow":{"names":["a"],"q":[[0,0,0,0,0]],"code":[[1]],"dtw_m":[[0]]}}})"),
                               "none");
  bad.movement = "elbow";
  bad.start_pose = {1.0, -0.2, 1.0, 0.5, 0.0};
  bad.ticks = 5;
  int status = 0;
  const std::string line = errorLine(bad, status);
  CHECK(line.find("\"run_codes\"") != std::string::npos);
  CHECK(status == 1);
}
