// The embedding example (examples/embed) against nao_rt: the example's controller and cycle
// (read -> update -> write), with nao_backends' ODE arm as the joint interface instead of the
// example's kinematic one, give nao_rt's first 100 ticks bit for bit for the same model and start
// (models/autonomous.bin, whole_arm, start 0).
#include "embed.hpp"

#include "rt_run.hpp"

#include "nao/arm_model_io.hpp"
#include "nao/sim_arm.hpp"

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

const std::string kModel = std::string(NAO_MODELS_DIR) + "/autonomous.bin";
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

}  // namespace

TEST_CASE("the embedding example on the ODE arm gives nao_rt's first 100 ticks bit for bit") {
  const fs::path dir = fs::temp_directory_path() / ("nao_test_embed_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  rt::RunOptions o;
  o.weights_path = kModel;
  o.reference = "none";
  o.movement = "whole_arm";
  o.start_index = 0;
  o.ticks = kTicks;
  o.log_dir = dir.string();
  std::ostringstream out, err;
  const rt::RunReport report = rt::runController<embed::Dims>(o, out, err);
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
  const ModelFile file = readModelFile(kModel);
  REQUIRE(file.header.movement_names[1] == "whole_arm");
  const std::vector<ModelStart> starts = readModelSpec(file.header, RetargetParams{}, kModel).starts[1];
  OdeArmBackend ode(arm, SimParams{}, clampToLimits(arm, starts[0].q));
  OdeJoints joints{ode};
  const auto c = embed::configure(kModel, arm);
  activateController(*c->model, *c->data, ode.activate(clampToLimits(arm, starts[0].q)), 1, c->clock);
  int differing = 0;
  for (int t = 0; t < kTicks; ++t) {
    const TickRecord& rec = embed::cycle(*c, joints, nullptr);
    const JointVector& q = joints.read();  // the arm at the end of the period, as ticks.csv's q
    const std::vector<std::string>& row = ticks[static_cast<std::size_t>(t)];
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
  deactivateController(*c->model, *c->data);
  CHECK_MESSAGE(differing == 0, "expected every q and attention score equal to nao_rt's, got " << differing
                                    << " differing of " << kTicks * kNumJoints * 2);
  fs::remove_all(dir);
}
