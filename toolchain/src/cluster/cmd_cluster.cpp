// nao_toolchain cluster: k-means++ key poses per movement over a retargeted data set.
#include "nao/tools/command.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/retarget_pipeline.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

struct Demo {
  std::string name;
  std::vector<double> t_s;      ///< measured samples only (they are clustered)
  std::vector<JointVector> q;
  std::vector<double> t_grid;   ///< every row of retarget.csv (the 10 Hz grid)
  std::vector<bool> measured;   ///< per grid row: a human arm was measured
};

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "cluster",
      "k-means++ key poses (paper §3.3, Algorithm 2) of every movement in a data set. Reads\n"
      "DATA/<movement>_<index>/retarget.csv (nao_toolchain retarget), clusters the joint poses of all\n"
      "demonstrations of a movement (samples without a measured human arm are left out), writes\n"
      "DATA/<demo>/features.csv (t_s, label, measured, f_0..4: the feature-extracted trajectory on\n"
      "the whole 10 Hz grid) and the centroids of every movement as JSON.");
  struct Args {
    std::string data, out, update = "mean", trajectory = "qr";
    int k = 10, max_iterations = 300;
    std::uint64_t seed = 1;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("--data", args->data, "Data set directory")->required()->check(CLI::ExistingDirectory);
  cmd->add_option("--out", args->out, "Centroids JSON (default: DATA/centroids.json)");
  cmd->add_option("--k", args->k, "Key poses per movement")->check(CLI::Range(1, 1000))->capture_default_str();
  cmd->add_option("--update", args->update, "Centroid update: mean (paper eq. 10) or median (paper Algorithm 2)")
      ->check(CLI::IsMember({"mean", "median"}))
      ->capture_default_str();
  cmd->add_option("--trajectory", args->trajectory,
                  "Robot trajectory to cluster: qr (the imitation reference, as retarget --priority chose it),\n"
                  "qx (hand priority) or qq (joint priority)")
      ->check(CLI::IsMember({"qr", "qx", "qq"}))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Seed of the k-means++ draws")->capture_default_str();
  cmd->add_option("--max-iterations", args->max_iterations, "Cap on assignment/update rounds")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->callback([args] {
    // Demonstrations by movement, in sorted directory order (deterministic).
    std::map<std::string, std::vector<Demo>> movements;
    std::vector<fs::path> dirs;
    for (const auto& entry : fs::directory_iterator(args->data))
      if (entry.is_directory() && fs::exists(entry.path() / "retarget.csv")) dirs.push_back(entry.path());
    std::sort(dirs.begin(), dirs.end());
    if (dirs.empty()) throw UserError(args->data + ": no <movement>_<index>/retarget.csv found (run retarget first)");
    RetargetParams setting;
    bool have_setting = false;
    for (const fs::path& dir : dirs) {
      const std::string name = dir.filename().string();
      const auto cut = name.rfind('_');
      if (cut == std::string::npos || cut == 0)
        throw UserError(dir.string() + ": directory name is not <movement>_<index>");
      Demo demo;
      demo.name = name;
      RetargetParams demo_setting;
      const std::vector<RetargetRow> rows = readRetargetCsv((dir / "retarget.csv").string(), &demo_setting);
      // One data set, one reference: demonstrations retargeted differently cannot share key poses.
      if (!have_setting) {
        setting = demo_setting;
        have_setting = !rows.empty();
      } else if (!rows.empty() && !sameRetargetSetting(setting, demo_setting)) {
        throw UserError((dir / "retarget.csv").string() + ": retargeted with " +
                        retargetSettingJson(demo_setting).dump() + ", the demonstrations before it with " +
                        retargetSettingJson(setting).dump());
      }
      for (const RetargetRow& r : rows) {
        const bool measured = (r.flags & kRowHumanMissing) == 0;
        demo.t_grid.push_back(r.t_s);
        demo.measured.push_back(measured);
        if (!measured) continue;  // a held pose is not a measured one
        demo.t_s.push_back(r.t_s);
        demo.q.push_back(args->trajectory == "qr"   ? r.result.q_r
                         : args->trajectory == "qq" ? r.result.q_q
                                                    : r.result.q_x);
      }
      if (demo.q.empty()) throw UserError(dir.string() + "/retarget.csv: no sample with a measured human arm");
      movements[name.substr(0, cut)].push_back(std::move(demo));
    }

    nlohmann::json out;
    out["k"] = args->k;
    out["update"] = args->update;
    out["trajectory"] = args->trajectory;
    out["retarget"] = retargetSettingJson(setting);
    out["seed"] = args->seed;
    std::uint64_t movement_index = 0;
    for (const auto& [movement, demos] : movements) {
      std::vector<JointVector> points;
      for (const Demo& d : demos) points.insert(points.end(), d.q.begin(), d.q.end());
      KMeansOptions options;
      options.k = args->k;
      options.update = args->update == "mean" ? CentroidUpdate::kMean : CentroidUpdate::kMedian;
      options.seed = args->seed + 1000003u * movement_index++;  // one stream per movement
      options.max_iterations = args->max_iterations;
      const KMeansResult r = kmeansPlusPlus(points, options);
      std::printf("cluster: %-10s %3zu demos, %6zu poses -> %d key poses in %d rounds (%s), F = %.4f rad^2\n",
                  movement.c_str(), demos.size(), points.size(), args->k, r.iterations,
                  r.converged ? "converged" : "cap hit", r.objective);
      auto& m = out["movements"][movement];
      m["demos"] = demos.size();
      m["poses"] = points.size();
      m["iterations"] = r.iterations;
      m["converged"] = r.converged;
      m["objective_rad2"] = r.objective;
      for (const JointVector& c : r.centroids) m["centroids"].push_back(std::vector<double>(c.data(), c.data() + kNumJoints));

      for (const Demo& d : demos) {
        // Segments come from the measured samples; the trajectory covers the whole grid. A row
        // without a measurement carries the label of the last measured one (the runtime holds
        // its last reference the same way); leading ones the first measured label.
        const std::vector<JointVector> f = featureTrajectory(r.centroids, d.t_s, d.q, d.t_grid);
        const fs::path path = fs::path(args->data) / d.name / "features.csv";
        std::ofstream csv(path);
        if (!csv) throw UserError("cannot write " + path.string());
        csv.precision(10);
        csv << "t_s,label,measured,f_0,f_1,f_2,f_3,f_4\n";
        const std::vector<int> labels = keyPoseLabels(r.centroids, d.t_s, d.q, d.t_grid);
        for (std::size_t i = 0; i < f.size(); ++i) {
          csv << d.t_grid[i] << ',' << labels[i] << ',' << (d.measured[i] ? 1 : 0);
          for (int j = 0; j < kNumJoints; ++j) csv << ',' << f[i][j];
          csv << '\n';
        }
      }
    }
    const std::string path = args->out.empty() ? (fs::path(args->data) / "centroids.json").string() : args->out;
    std::ofstream json(path);
    if (!json) throw UserError("cannot write " + path);
    json << out.dump(2) << '\n';
    std::printf("cluster: centroids -> %s, feature trajectories -> <demo>/features.csv\n", path.c_str());
  });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(cluster, nao::tools::setup)
