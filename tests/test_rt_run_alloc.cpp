// Real-time property of a whole nao_rt run: from activate through 6,000 ticks (10 simulated
// minutes: the reference ends after its demonstration, so the no-human hold and the return home
// run too), with the ring push and the per-tick records, nothing is allocated; summary.json
// reports the count. The same for a shorter run with --precision int8.
#include "rt_run.hpp"

#include "nao/model_file.hpp"
#include "alloc_probe.hpp"
#include "support/random_policy.hpp"
#include "support/reference_files.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <filesystem>
#include <optional>
#include <sstream>

using namespace nao;

TEST_CASE("a 6,000-tick nao_rt run allocates nothing after activate, and summary.json says so") {
  namespace fs = std::filesystem;
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  ModelHeader h;
  h.arch = smallArch();
  h.joints = trainedJoints(arm);
  h.movement_names = {"elbow", "whole_arm", "wrist"};
  h.metadata_json = "{}";
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / ("rt_run_alloc_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string model = (dir / "model.bin").string();
  writeModelFile(model, h, test::makeRandomPolicy(h.arch, arm, 11).tensors);

  rt::RunOptions o;
  o.weights_path = model;
  o.reference = "file:" + test::syntheticReferenceCsv("whole_arm", 2, dir);
  o.movement = "whole_arm";
  o.ticks = 6000;
  o.log_dir = (dir / "run").string();
  CountingProbe probe;
  std::ostringstream out, err;
  const rt::RunReport r = rt::runController<SmallPolicyDims>(o, out, err, &probe);
  REQUIRE_MESSAGE(r.status == 0, r.error);
  CHECK(r.ticks == 6000);
  CHECK(r.allocations_after_activate == 0);
  const nlohmann::json s = nlohmann::json::parse(r.summary_json);
  CHECK(s["allocations_after_activate"] == 0);
  // The fault paths ran inside the counted window (a non-finite action's path: test_controller_alloc).
  CHECK(s["faults"]["no_human"] > 0);
  CHECK(s["faults"]["human_timeout"] > 0);
  // The ring kept the last kDefaultAttentionCapacity records.
  CHECK(s["attention"]["records_written"] == 6000);
  CHECK(s["attention"]["record_count"] == kDefaultAttentionCapacity);
  CHECK(s["attention"]["first_record"] == 6000 - kDefaultAttentionCapacity);

  // --precision int8: the quantised tokens and sums live on the stack; 1,000 ticks.
  o.precision = "int8";
  o.ticks = 1000;
  o.log_dir = (dir / "run_int8").string();
  const rt::RunReport r8 = rt::runController<SmallPolicyDims>(o, out, err, &probe);
  REQUIRE_MESSAGE(r8.status == 0, r8.error);
  CHECK(r8.allocations_after_activate == 0);
  CHECK(nlohmann::json::parse(r8.summary_json)["model"]["precision"] == "int8");
  fs::remove_all(dir);
}
