// The committed models beat the two trivial predictors on their own validation split, as their
// model cards state: the validation demonstrations named in model.bin are regenerated from the
// synthesiser (training set seed 1, as toolchain/nao train makes it), the samples are rebuilt
// as docs/policy.md defines them, and the runtime's inference is scored against the zero action
// and the repeat-last-action baselines.
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/reference_source.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

using namespace nao;

namespace {

constexpr std::uint64_t kTrainingSeed = 1;  // toolchain/nao train: synth --seed 1

struct Scores {
  double model = 0.0, zero = 0.0, repeat = 0.0;
  std::size_t samples = 0;
};

Scores score(const std::string& path) {
  const ArmModel arm = loadArmModel(nao::test::kUrdfPath);
  const ModelFile model = readModelFile(path);
  checkJointsMatch(model, arm, path);
  checkPolicyArch<PaperPolicyDims>(model.header.arch);
  std::vector<const float*> p;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) p.push_back(model.data(i));
  const PolicyWeights<PaperPolicyDims> w =
      bindPolicyWeights<PaperPolicyDims>(p.data(), p.size(), model.header.conditioning);
  auto ws = makePolicyWorkspace<PaperPolicyDims>();

  const nlohmann::json meta = nlohmann::json::parse(model.header.metadata_json);
  const std::vector<std::string> val = meta.at("split").at("val").get<std::vector<std::string>>();
  REQUIRE(val.size() >= 3);
  Scores s;
  double sum_model = 0.0, sum_zero = 0.0, sum_repeat = 0.0;
  for (const std::string& name : val) {
    const std::size_t cut = name.rfind('_');
    const std::string movement = name.substr(0, cut);
    const int index = std::stoi(name.substr(cut + 1));
    int m = -1;
    for (std::size_t k = 0; k < model.header.movement_names.size(); ++k)
      if (model.header.movement_names[k] == movement) m = static_cast<int>(k);
    REQUIRE(m >= 0);
    std::vector<JointVector> centroids;
    for (int k = 0; k < PaperPolicyDims::kClusters; ++k) centroids.push_back(centroid(w, m, k).cast<double>());
    const tools::ReferenceStream ref =
        tools::makeDemoReference(arm, tools::parseMovement(movement), kTrainingSeed, index, centroids);
    // Labels as nao_toolchain cluster writes them (the key pose in force at each tick).
    std::vector<double> t_grid, t_meas;
    std::vector<JointVector> q_meas;
    for (std::size_t t = 0; t < ref.retargeted.size(); ++t) {
      t_grid.push_back(static_cast<double>(t) / ref.rate_hz);
      if (!ref.measured[t]) continue;
      t_meas.push_back(t_grid.back());
      q_meas.push_back(ref.retargeted[t]);
    }
    REQUIRE(!q_meas.empty());
    const std::vector<int> labels = tools::keyPoseLabels(centroids, t_meas, q_meas, t_grid);
    const std::vector<JointVector>& f = ref.target;
    for (std::size_t t = 0; t + 1 < f.size(); ++t) {
      const JointVector a_prev = t == 0 ? JointVector::Zero() : JointVector(f[t] - f[t - 1]);
      const JointVector target = f[t + 1] - f[t];
      PolicyInput in;
      in.q = f[t].cast<float>();
      in.a_prev = a_prev.cast<float>();
      in.r = centroids[static_cast<std::size_t>(labels[t])].cast<float>();
      in.movement = m;
      in.step = static_cast<int>(std::min<std::size_t>(t, PaperPolicyDims::kMaxSteps - 1));
      const JointVector a = stepPolicy(w, *ws, in).cast<double>();
      sum_model += (a - target).squaredNorm();
      sum_zero += target.squaredNorm();
      sum_repeat += (a_prev - target).squaredNorm();
      ++s.samples;
    }
  }
  const double n = static_cast<double>(s.samples * kNumJoints);
  s.model = sum_model / n;
  s.zero = sum_zero / n;
  s.repeat = sum_repeat / n;
  MESSAGE(path << ": " << val.size() << " validation demonstrations, " << s.samples << " samples; MSE rad^2: model "
               << s.model << ", zero action " << s.zero << ", repeat last " << s.repeat);
  // The card's numbers (training pipeline: files, Ceres) are reproduced closely by the
  // in-memory pipeline (no pixel rounding, runtime LM).
  const nlohmann::json& base = meta.at("baselines_rad2").at("val");
  CHECK(s.zero == doctest::Approx(base.at("zero_action").get<double>()).epsilon(0.05));
  CHECK(s.repeat == doctest::Approx(base.at("repeat_last").get<double>()).epsilon(0.05));
  CHECK(s.model == doctest::Approx(meta.at("result").at("val_mse_rad2").get<double>()).epsilon(0.10));
  return s;
}

std::string modelPath(const char* name) {
  return (std::filesystem::path(NAO_TEST_DATA_DIR).parent_path().parent_path() / "models" / name).string();
}

}  // namespace

TEST_CASE("models/default.bin beats both baselines and reaches at most half the repeat-last-action MSE") {
  const Scores s = score(modelPath("default.bin"));
  CHECK(s.model < s.zero);
  CHECK(s.model < s.repeat);
  CHECK(s.model <= 0.5 * s.repeat);
}

TEST_CASE("models/autonomous.bin beats both baselines on its validation split") {
  const Scores s = score(modelPath("autonomous.bin"));
  CHECK(s.model < s.zero);
  CHECK(s.model < s.repeat);
}
