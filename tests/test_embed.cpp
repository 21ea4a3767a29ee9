// The embedding example (examples/embed) against nao_rt: the example's controller and cycle
// (read -> update -> write), with nao_backends' ODE arm as the joint interface instead of the
// example's kinematic one, give nao_rt's first 100 ticks bit for bit for the same model and start:
// models/autonomous.bin (small dimensions, autonomous, whole_arm from start 0) and
// models/default.bin (paper dimensions, reference mode, a recorded elbow reference). And a
// ControllerModel outlives the ModelFile it was configured from.
#include "embed.hpp"

#include "rt_run.hpp"

#include "nao/arm_model_io.hpp"
#include "nao/reference_stream.hpp"
#include "nao/sim_arm.hpp"

#include "support/reference_files.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <unistd.h>

#include <charconv>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using namespace nao;

namespace {

const std::string kAutonomous = std::string(NAO_MODELS_DIR) + "/autonomous.bin";
const std::string kReference = std::string(NAO_MODELS_DIR) + "/default.bin";
constexpr int kTicks = 100;

// The rows of ticks.csv as text cells; the header's column names into `columns`.
std::vector<std::vector<std::string>> readTicks(const fs::path& path, std::vector<std::string>& columns) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::stringstream header(line);
  for (std::string c; std::getline(header, c, ',');) columns.push_back(c);
  std::vector<std::vector<std::string>> rows;
  while (std::getline(in, line)) {
    std::vector<std::string> row;
    std::stringstream cells(line);
    for (std::string c; std::getline(cells, c, ',');) row.push_back(c);
    rows.push_back(row);
  }
  return rows;
}

// The ODE arm as a framework's joint interface (read, write), as embed::cycle drives one.
struct OdeJoints {
  OdeArmBackend& ode;
  const JointVector& read() const { return ode.measured(); }
  void write(const JointVector& q_cmd) { ode.command(q_cmd); }
};

// A cell as the number it was written from: ticks.csv holds the shortest text that reads back
// as the exact double (q) or float (attention).
template <class T>
T number(const std::string& cell) {
  T v{};
  std::from_chars(cell.data(), cell.data() + cell.size(), v);
  return v;
}

// What one run is: the model, its movement, and the human frames (none: autonomous, from start 0).
struct RunCase {
  std::string model;
  std::string movement;
  std::string skeleton_csv;  ///< empty: autonomous
};

// nao_rt's first kTicks ticks (in process, Dims compiled) and the example's on the ODE arm, compared
// cell by cell: q and the attention bit for bit, the fault bits equal.
template <class Dims>
void compareWithNaoRt(const RunCase& rc) {
  const fs::path dir = fs::temp_directory_path() / ("nao_test_embed_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  rt::RunOptions o;
  o.weights_path = rc.model;
  o.reference = rc.skeleton_csv.empty() ? std::string("none") : "file:" + rc.skeleton_csv;
  o.movement = rc.movement;
  if (rc.skeleton_csv.empty()) o.start_index = 0;
  o.ticks = kTicks;
  o.log_dir = dir.string();
  std::ostringstream out, err;
  const rt::RunReport report = rt::runController<Dims>(o, out, err);
  REQUIRE_MESSAGE(report.status == 0, "nao_rt's run failed: " << report.error);
  std::vector<std::string> columns;
  const std::vector<std::vector<std::string>> ticks = readTicks(dir / "ticks.csv", columns);
  REQUIRE(ticks.size() == static_cast<std::size_t>(kTicks));
  auto column = [&](const std::string& name) {
    const auto it = std::find(columns.begin(), columns.end(), name);
    REQUIRE_MESSAGE(it != columns.end(), "ticks.csv has no column " << name);
    return static_cast<std::size_t>(it - columns.begin());
  };

  const ArmModel arm = loadArmModel(test::kUrdfPath);
  const ModelFile file = readModelFile(rc.model);
  const ModelSpec spec = readModelSpec(file.header, RetargetParams{}, rc.model);
  const auto mv = std::find(spec.movement_names.begin(), spec.movement_names.end(), rc.movement);
  REQUIRE(mv != spec.movement_names.end());
  const int movement = static_cast<int>(mv - spec.movement_names.begin());
  // The frames nao_rt sees and its start: a recorded reference's (with the demonstration's
  // calibrated human scale, as nao_rt configures it), or the model's start 0.
  ControllerParams params;
  ReferenceStream reference;
  JointVector q0;
  if (rc.skeleton_csv.empty()) {
    q0 = spec.starts[static_cast<std::size_t>(movement)][0].q;
  } else {
    reference = makeFileReference(arm, rc.skeleton_csv, rc.movement, modelKeyPoses(file, movement), spec.retarget);
    params.human = reference.human;
    q0 = reference.target.front();
  }
  OdeArmBackend ode(arm, SimParams{}, clampToLimits(arm, q0));
  OdeJoints joints{ode};
  const auto c = embed::configure<Dims>(file, rc.model, arm, params);
  activateController(c->model, *c->data, ode.activate(clampToLimits(arm, q0)), movement, c->clock);
  int differing = 0;
  for (int t = 0; t < kTicks; ++t) {
    const std::size_t i = static_cast<std::size_t>(t);
    const SkeletonFrame* frame =
        i < reference.frames.size() && reference.present[i] ? &reference.frames[i] : nullptr;
    const TickRecord& rec = embed::cycle(*c, joints, frame);
    const JointVector& q = joints.read();  // the arm at the end of the period, as ticks.csv's q
    const std::vector<std::string>& row = ticks[i];
    for (int j = 0; j < kNumJoints; ++j) {
      const double q_rt = number<double>(row[column("q_" + std::to_string(j))]);
      const float att_rt = number<float>(row[column("att_" + std::to_string(j))]);
      if (q[j] != q_rt || rec.att[static_cast<std::size_t>(j)] != att_rt) {
        if (++differing <= 5)
          MESSAGE("tick " << t << " joint " << j << ": nao_rt q " << q_rt << " att " << att_rt << ", example q "
                          << q[j] << " att " << rec.att[static_cast<std::size_t>(j)]);
      }
    }
    CHECK_MESSAGE(rec.fault == number<std::uint32_t>(row[column("fault")]),
                  "tick " << t << ": nao_rt's fault bits " << row[column("fault")] << ", the example's " << rec.fault);
  }
  deactivateController(c->model, *c->data);
  CHECK_MESSAGE(differing == 0, "expected every q and attention score equal to nao_rt's, got " << differing
                                    << " differing of " << kTicks * kNumJoints * 2);
  fs::remove_all(dir);
}

}  // namespace

TEST_CASE("the embedding example on the ODE arm gives nao_rt's first 100 ticks bit for bit: autonomous.bin") {
  compareWithNaoRt<SmallPolicyDims>({kAutonomous, "whole_arm", ""});
}

TEST_CASE("the embedding example on the ODE arm gives nao_rt's first 100 ticks bit for bit: default.bin, a recorded reference") {
  const fs::path refs = fs::temp_directory_path() / ("nao_test_embed_refs_" + std::to_string(::getpid()));
  compareWithNaoRt<PaperPolicyDims>({kReference, "elbow", test::syntheticReferenceCsv("elbow", 1, refs)});
  fs::remove_all(refs);
}

TEST_CASE("the embedding example's architectures: each committed model runs with its own, another is refused") {
  int small = 0, paper = 0;
  withPolicyDims<PaperPolicyDims, SmallPolicyDims>(readModelFile(kAutonomous).header.arch, [&](auto dims) {
    small = std::is_same_v<decltype(dims), SmallPolicyDims>;
    return 0;
  });
  withPolicyDims<PaperPolicyDims, SmallPolicyDims>(readModelFile(kReference).header.arch, [&](auto dims) {
    paper = std::is_same_v<decltype(dims), PaperPolicyDims>;
    return 0;
  });
  CHECK(small == 1);
  CHECK(paper == 1);
  PolicyArch other = smallArch();
  other.window = 24;
  const auto run_other = [&] { return withPolicyDims<PaperPolicyDims, SmallPolicyDims>(other, [](auto) { return 0; }); };
  CHECK_THROWS_AS(run_other(), std::invalid_argument);
}

// Ticks of a controller: q_cmd and the attention of each, from `q0` with the arm taking each command.
template <class Dims>
std::vector<TickRecord> ticksOf(const ControllerModel<Dims>& model, const JointVector& q0, int movement) {
  struct ZeroClock final : ControllerClock {
    std::int64_t nowNs() override { return 0; }
  } clock;
  auto data = std::make_unique<ControllerData<Dims>>();
  JointVector q = q0;
  activateController(model, *data, q, movement, clock);
  std::vector<TickRecord> out;
  for (int t = 0; t < 50; ++t) {
    out.push_back(updateController(model, *data, q, nullptr));
    q = out.back().q_cmd;
  }
  return out;
}

TEST_CASE("a ControllerModel outlives the ModelFile it was configured from: the same ticks bit for bit") {
  const ArmModel arm = loadArmModel(test::kUrdfPath);
  auto file = std::make_unique<ModelFile>(readModelFile(kAutonomous));
  const ControllerModel<SmallPolicyDims> orphan = configureController(
      arm, readModelSpec(file->header, RetargetParams{}, kAutonomous), bindPolicyWeights<SmallPolicyDims>(*file));
  const JointVector q0 = clampToLimits(arm, orphan.spec.starts[1][0].q);
  const std::vector<TickRecord> before = ticksOf(orphan, q0, 1);
  // The file's bytes overwritten, then the file destroyed: nothing the model reads was in them.
  std::fill(file->bytes.begin(), file->bytes.end(), std::uint8_t{0xff});
  file.reset();
  const std::vector<TickRecord> after = ticksOf(orphan, q0, 1);
  REQUIRE(after.size() == before.size());
  for (std::size_t t = 0; t < after.size(); ++t) {
    CHECK(after[t].q_cmd == before[t].q_cmd);
    CHECK(after[t].att == before[t].att);
  }
  // Copies share the weights' storage: the model's floats live as long as any of them.
  const ControllerModel<SmallPolicyDims> copy = orphan;
  CHECK(copy.policy.storage == orphan.policy.storage);
  CHECK(copy.policy.q_mean.data() == orphan.policy.q_mean.data());
}
