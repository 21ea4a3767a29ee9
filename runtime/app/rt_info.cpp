#include "rt_info.hpp"

#include "nao/arm_model.hpp"
#include "nao/arm_model_io.hpp"
#include "nao/policy_kernels.hpp"
#include "nao/quantize.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <ostream>
#include <vector>

namespace nao::rt {
namespace {

/// One line, whatever the message holds.
std::string oneLine(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  return s;
}

}  // namespace

std::string modelInfoJson(const ModelFile& model, const std::string& source, const std::string& precision,
                          PolicyKernel kernel, std::optional<bool> runs) {
  using nlohmann::ordered_json;
  const ModelHeader& h = model.header;
  const PolicyArch& a = h.arch;
  char checksum[32];
  std::snprintf(checksum, sizeof checksum, "0x%016llx", static_cast<unsigned long long>(model.checksum));

  ordered_json j;
  j["format_version"] = kModelFormatVersion;
  j["d_model"] = a.d_model;
  j["heads"] = a.heads;
  j["encoder_layers"] = a.encoder_layers;
  j["decoder_layers"] = a.decoder_layers;
  j["ffn_hidden"] = a.ffn_hidden;
  j["tokens"] = a.tokens;
  j["features"] = a.features;
  j["conditioning"] = conditioningName(h.conditioning);
  j["clusters"] = a.clusters;
  j["movements"] = h.movement_names;
  j["max_steps"] = a.max_steps;
  j["window"] = a.window;  // W, ticks of history the policy attends to
  j["parameters"] = parameterCount(a);
  j["tensors"] = model.tensors.size();
  j["bytes"] = model.size();
  j["checksum"] = checksum;
  // The contract: where the weights come from and their precision.
  j["weights"] = source == "compiled-in" ? "compiled" : "file";
  j["precision"] = precision;
  // The kernel a run binds the weights with: every kernel gives the same bits.
  j["kernel"] = policyKernelName(kernel);
  ordered_json joints = ordered_json::array();
  for (const TrainedJoint& t : h.joints)
    joints.push_back({{"name", t.name}, {"lower", t.lower}, {"upper", t.upper}, {"velocity", t.velocity}});
  j["joints"] = std::move(joints);
  const ModelSpec spec = readModelSpec(h, RetargetParams{}, source);
  // The autonomous starts per movement (nao_rt --reference none --start I): name and length.
  const ModelStarts& starts = spec.starts;
  ordered_json by_movement = ordered_json::object();
  for (std::size_t m = 0; m < starts.size(); ++m) {
    ordered_json list = ordered_json::array();
    for (const ModelStart& s : starts[m]) list.push_back({{"name", s.name}, {"ticks", s.ticks}});
    by_movement[h.movement_names[m]] = std::move(list);
  }
  j["starts"] = std::move(by_movement);
  // A run latent's codes per movement (chosen at activate): how many, not the table itself.
  const std::vector<ModelRunCodes>& codes = spec.run_codes;
  ordered_json code_counts = ordered_json::object();
  for (std::size_t m = 0; m < h.movement_names.size(); ++m) code_counts[h.movement_names[m]] = m < codes.size() ? codes[m].size() : 0;
  j["run_codes"] = std::move(code_counts);
  ordered_json metadata = ordered_json::parse(h.metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!metadata.is_discarded() && metadata.is_object()) metadata.erase("run_codes");
  j["metadata"] = metadata.is_discarded() ? ordered_json(h.metadata_json) : std::move(metadata);
  j["source"] = source;
  if (runs) j["runs"] = *runs;  // whether --weights of this file runs here or needs a nao_rt of its own
  // Metadata is whatever the file holds: replace invalid UTF-8 rather than throw.
  return j.dump(2, ' ', false, ordered_json::error_handler_t::replace);
}

int runInfo(const InfoOptions& options, std::ostream& out, std::ostream& err) {
  try {
    ModelFile model;
    std::string source;
    if (!options.weights_path.empty()) {
      source = options.weights_path;
      model = readModelFile(source);
    } else if (options.compiled.bytes != nullptr) {
      source = "compiled-in";
      model = mappedModelFile(options.compiled, "compiled-in model");
    } else {
      err << "nao_rt: no model is compiled into this build; pass --weights FILE\n";
      return 1;
    }
    const ArmModel arm = loadArmModel(options.urdf_path);
    try {
      checkJointsMatch(model, arm, source == "compiled-in" ? "compiled-in model" : source);
    } catch (const ModelFileError& e) {
      throw ModelFileError(std::string(e.what()) + " (" + options.urdf_path + ")");
    }
    const WeightPrecision precision = runPrecision(options.precision, source == "compiled-in", options.compiled);
    requirePolicyKernel(options.kernel);  // what a run's binding would refuse
    std::optional<bool> runs;
    if (options.computes) runs = options.computes(model.header.arch);
    out << modelInfoJson(model, source, weightPrecisionName(precision), options.kernel, runs) << "\n";
    return 0;
  } catch (const std::exception& e) {
    err << "nao_rt: " << oneLine(e.what()) << "\n";
    return 1;
  }
}

}  // namespace nao::rt
