// nao_toolchain model-starts (nao/tools/model_starts.hpp): a model's autonomous starts from its
// data set — the held-out demonstrations' first retargeted poses and lengths — written into its
// metadata, the tensors untouched.
#include "nao/tools/model_starts.hpp"

#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/retarget_pipeline.hpp"
#include "support/random_policy.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>

using namespace nao;
using namespace nao::tools;

namespace {

namespace fs = std::filesystem;

// A demonstration folder of a clustered data set: retarget.csv (its first row's q_r is q0) and
// features.csv with `ticks` rows.
void writeDemo(const fs::path& dir, const JointVector& q0, int ticks) {
  fs::create_directories(dir);
  std::vector<RetargetRow> rows(static_cast<std::size_t>(ticks));
  for (int i = 0; i < ticks; ++i) {
    RetargetRow& r = rows[static_cast<std::size_t>(i)];
    r.t_s = 0.1 * i;
    r.result.q_r = q0 + JointVector::Constant(0.01 * i);  // only the first row is the start
    r.result.q_x = r.result.q_q = r.result.q_r;
  }
  writeRetargetCsv((dir / "retarget.csv").string(), rows, RetargetParams{});
  std::ofstream f(dir / "features.csv");
  f << "t_s,label,measured,f_0,f_1,f_2,f_3,f_4\n";
  for (int i = 0; i < ticks; ++i) f << 0.1 * i << ",0,1,0,0,0,0,0\n";
}

}  // namespace

TEST_CASE("model-starts writes the held-out demonstrations' first retargeted poses and lengths, by movement in split.val order, and nothing else") {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / ("model_starts_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const JointVector qa = (JointVector() << 1.2, -0.3, 1.0, 0.6, 0.1).finished();
  const JointVector qb = (JointVector() << 0.9, -0.5, 0.8, 0.9, -0.2).finished();
  const JointVector qc = (JointVector() << 1.4, -0.2, 1.2, 0.5, 0.0).finished();
  writeDemo(dir / "data" / "elbow_010", qa, 12);
  writeDemo(dir / "data" / "elbow_003", qb, 7);
  writeDemo(dir / "data" / "wrist_001", qc, 9);
  writeDemo(dir / "data" / "elbow_000", qc, 3);  // a training demonstration: no start

  ModelHeader h;
  h.arch = smallArch();
  h.conditioning = Conditioning::kAutonomous;
  h.joints = trainedJoints(arm);
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = R"({"split":{"train":["elbow_000"],"val":["elbow_010","wrist_001","elbow_003"]}})";
  const std::string in = (dir / "in.bin").string(), out = (dir / "out.bin").string();
  writeModelFile(in, h, test::makeRandomPolicy(h.arch, arm, 3).tensors);
  const ModelFile model = readModelFile(in);

  const ModelStarts written = addModelStarts(model, (dir / "data").string(), out);
  const ModelFile back = readModelFile(out);
  const ModelStarts starts = modelStarts(back.header.metadata_json, back.header.movement_names, out);
  REQUIRE(starts.size() == 3);
  REQUIRE(starts[0].size() == 2);
  CHECK(starts[0][0].name == "elbow_010");
  CHECK(starts[0][0].ticks == 12);
  CHECK((starts[0][0].q - qa).cwiseAbs().maxCoeff() < 1e-9);  // retarget.csv keeps 10 digits
  CHECK(starts[0][1].name == "elbow_003");
  CHECK(starts[0][1].ticks == 7);
  CHECK((starts[0][1].q - qb).cwiseAbs().maxCoeff() < 1e-9);
  CHECK(starts[1].empty());
  REQUIRE(starts[2].size() == 1);
  CHECK(starts[2][0].name == "wrist_001");
  CHECK(starts[2][0].ticks == 9);
  CHECK(starts[0][0].q == written[0][0].q);

  // The rest of the model is the one read: header, the other metadata, every tensor's bytes.
  CHECK(back.header.arch == model.header.arch);
  CHECK(back.header.conditioning == model.header.conditioning);
  CHECK(back.header.movement_names == model.header.movement_names);
  CHECK(back.header.metadata_json.rfind(R"({"split":{"train":["elbow_000"],"val":["elbow_010","wrist_001","elbow_003"]},"starts":)", 0) == 0);
  REQUIRE(back.tensors.size() == model.tensors.size());
  for (std::size_t i = 0; i < model.tensors.size(); ++i)
    CHECK(std::memcmp(back.data(i), model.data(i), model.tensors[i].spec.count() * sizeof(float)) == 0);

  // A held-out demonstration missing from the data set, or a model without split.val, is refused.
  fs::remove_all(dir / "data" / "elbow_003");
  CHECK_THROWS_WITH_AS(heldOutStarts(h, (dir / "data").string()), doctest::Contains("elbow_003"), UserError);
  ModelHeader no_split = h;
  no_split.metadata_json = "{}";
  CHECK_THROWS_WITH_AS(heldOutStarts(no_split, (dir / "data").string()), doctest::Contains("split.val"), UserError);
  ModelHeader other = h;
  other.metadata_json = R"({"split":{"val":["wave_001"]}})";
  CHECK_THROWS_WITH_AS(heldOutStarts(other, (dir / "data").string()), doctest::Contains("wave_001"), UserError);
  fs::remove_all(dir);
}
