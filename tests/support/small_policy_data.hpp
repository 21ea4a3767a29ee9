// The small clustered policy data set the libtorch training tests share (test_torch_*.cpp).
#pragma once

#include "nao/model_file.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "policy_torch.hpp"
#include "policy_train.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace nao::test {

// Smooth circle-like joint trajectories (3 movements x 4 demos, 10 Hz), clustered with the
// project's own k-means++ into K = 10 key poses per movement and feature-extracted, as
// `nao_toolchain cluster` does.
inline const nao::tools::PolicyData& smallData() {
  static const nao::tools::PolicyData data = [] {
    const char* names[] = {"elbow", "whole_arm", "wrist"};
    std::map<std::string, std::vector<JointVector>> centroids;
    std::vector<nao::tools::PolicyDemo> demos;
    for (int m = 0; m < 3; ++m) {
      std::vector<std::vector<JointVector>> qs;
      std::vector<std::vector<double>> ts;
      std::vector<JointVector> all;
      for (int i = 0; i < 4; ++i) {
        const int n = 50 + 7 * i;
        std::vector<JointVector> q;
        std::vector<double> t_s;
        for (int t = 0; t < n; ++t) {
          const double phase = 2.0 * 3.14159265358979 * t / (25.0 + 3 * i) + 0.4 * i;
          JointVector v;
          for (int j = 0; j < kNumJoints; ++j)
            v[j] = 0.2 * (j + 1) - 0.3 * m + (0.15 + 0.1 * m) * std::sin(phase + 0.9 * j) * std::min(1.0, t / 10.0);
          q.push_back(v);
          t_s.push_back(0.1 * t);
        }
        all.insert(all.end(), q.begin(), q.end());
        qs.push_back(q);
        ts.push_back(t_s);
      }
      nao::tools::KMeansOptions options;
      options.seed = 5 + static_cast<std::uint64_t>(m);
      const nao::tools::KMeansResult km = nao::tools::kmeansPlusPlus(all, options);
      centroids[names[m]] = km.centroids;
      for (int i = 0; i < 4; ++i) {
        nao::tools::PolicyDemo d;
        d.name = std::string(names[m]) + "_00" + std::to_string(i);
        d.t_s = ts[static_cast<std::size_t>(i)];
        d.f = nao::tools::featureTrajectory(km.centroids, d.t_s, qs[static_cast<std::size_t>(i)]);
        for (const JointVector& q : qs[static_cast<std::size_t>(i)]) d.label.push_back(nao::tools::nearestCentroid(km.centroids, q));
        demos.push_back(d);
      }
    }
    return nao::tools::makePolicyData(centroids, demos);
  }();
  return data;
}

// The simulated arm the training rollouts are executed on (the project's URDF, default servos).
inline const nao::SimModel& smallSim() {
  static const nao::SimModel sim = nao::makeSimModel(nao::loadArmModel(nao::test::kUrdfPath));
  return sim;
}

// Training options of the small configuration on smallData(): `epochs` epochs (and as patience),
// a quarter held out, lr 1e-3 so that a few epochs show progress.
inline nao::tools::TrainOptions smallOptions(std::uint64_t seed, int epochs) {
  nao::tools::TrainOptions o;
  o.config_name = "small";
  o.arch = nao::smallArch();
  o.seed = seed;
  o.max_epochs = epochs;
  o.patience = epochs;
  o.val_fraction = 0.25;
  o.lr = 1e-3;
  return o;
}

// model.bin of a training on smallData() with `o` (the URDF's joints), and the result.
inline std::vector<std::uint8_t> trainBytes(const nao::tools::TrainOptions& o, nao::tools::TrainResult* out = nullptr) {
  nao::tools::TrainResult r = nao::tools::trainPolicy(smallData(), smallSim(), o, nullptr);
  std::vector<std::uint8_t> bytes =
      nao::encodeModel(nao::tools::modelHeader(smallData(), o, r, nao::trainedJoints(nao::loadArmModel(kUrdfPath))),
                       nao::tools::manifestFloats(r.net));
  if (out) *out = r;
  return bytes;
}

// model.bin of `full` (2 epochs) trained as one epoch, checkpointed at `checkpoint`, and resumed
// from it for the second; the checkpoint is removed afterwards. Equal to trainBytes(full) when the
// checkpoint holds everything the run carries over.
inline std::vector<std::uint8_t> resumedBytes(const nao::tools::TrainOptions& full, const std::string& checkpoint,
                                              nao::tools::TrainResult* out = nullptr) {
  nao::tools::TrainOptions first = full;
  first.max_epochs = 1;
  first.checkpoint = checkpoint;
  nao::tools::trainPolicy(smallData(), smallSim(), first, nullptr);
  REQUIRE(std::filesystem::exists(checkpoint));
  nao::tools::TrainOptions rest = full;
  rest.resume = checkpoint;
  std::vector<std::uint8_t> bytes = trainBytes(rest, out);
  std::filesystem::remove(checkpoint);
  return bytes;
}

}  // namespace nao::test
