// nao_toolchain model-starts: the autonomous starts of a model.bin from its data set
// (nao/tools/model_starts.hpp).
#include "nao/tools/model_starts.hpp"

#include "nao/csv_reader.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/policy_dataset.hpp"
#include "nao/tools/retarget_pipeline.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

// The card's "## Autonomous starts" section (replaced when there is one): what nao_rt --reference
// none --start I rolls out from.
void writeCardSection(const std::string& card, const ModelHeader& h, const ModelStarts& starts) {
  std::string text;
  {
    std::ifstream in(card);
    if (!in) throw UserError("cannot read the model card " + card);
    std::ostringstream s;
    s << in.rdbuf();
    text = s.str();
  }
  const std::string heading = "## Autonomous starts\n";
  if (const auto at = text.find(heading); at != std::string::npos) {
    const auto next = text.find("\n## ", at + heading.size());
    text.erase(at, next == std::string::npos ? std::string::npos : next + 1 - at);
  }
  if (!text.empty() && text.back() != '\n') text += '\n';
  if (!text.empty() && text.compare(text.size() - 2, 2, "\n\n") != 0) text += '\n';
  std::ostringstream sec;
  sec << heading << "\n"
      << "model.bin's metadata \"starts\" (nao_toolchain model-starts): per movement, the held-out demonstrations'\n"
      << "start states (the first retargeted pose of each, at rest) and lengths; `nao_rt --reference none\n"
      << "--movement M --start I` rolls out from the I-th.\n\n"
      << "| movement | starts | demonstrations (ticks) |\n|---|---|---|\n";
  for (std::size_t m = 0; m < starts.size(); ++m) {
    sec << "| " << h.movement_names[m] << " | " << starts[m].size() << " | ";
    for (std::size_t i = 0; i < starts[m].size(); ++i)
      sec << (i > 0 ? ", " : "") << starts[m][i].name << " (" << starts[m][i].ticks << ")";
    sec << " |\n";
  }
  text += sec.str();
  std::ofstream out(card, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw UserError("cannot write the model card " + card);
}

std::int64_t gridRows(const fs::path& features_csv) {
  CsvReader csv(features_csv.string(), "features CSV");
  std::int64_t rows = 0;
  while (csv.next()) ++rows;
  return rows;
}

void setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "model-starts",
      "Writes the autonomous starts of a model (model.bin metadata \"starts\", docs/nao_rt.md) from the\n"
      "data set it was trained on: for every held-out demonstration (its split.val), by movement, the\n"
      "name, the length in 10 Hz ticks (rows of DATA/<demo>/features.csv) and the start pose (the first\n"
      "qr_0..4 of DATA/<demo>/retarget.csv). The model is written to --out with only its metadata\n"
      "changed (tensors untouched); nao_rt --reference none --start I rolls out from them. When the\n"
      "model records its data fingerprint, DATA must be that data set. --card writes the starts into the\n"
      "model card too.");
  struct Args {
    std::string model, data, out, card;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("--model", args->model, "model.bin to read")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", args->data, "The model's data set (nao_toolchain cluster's directory, out/train/data)")
      ->required()
      ->check(CLI::ExistingDirectory);
  cmd->add_option("--out", args->out, "model.bin to write (may be --model)")->required();
  cmd->add_option("--card", args->card, "Model card (models/<name>.md) whose \"Autonomous starts\" section to write")
      ->check(CLI::ExistingFile);
  cmd->callback([args] {
    const ModelFile model = readModelFile(args->model);
    const ModelStarts starts = addModelStarts(model, args->data, args->out);
    if (!args->card.empty()) writeCardSection(args->card, model.header, starts);
    for (std::size_t m = 0; m < starts.size(); ++m)
      std::printf("%-10s %zu start(s)\n", model.header.movement_names[m].c_str(), starts[m].size());
    std::printf("wrote %s\n", args->out.c_str());
  });
}

}  // namespace

ModelStarts heldOutStarts(const ModelHeader& header, const std::string& data_dir) {
  const nlohmann::json meta = nlohmann::json::parse(header.metadata_json, nullptr, /*allow_exceptions=*/false);
  if (!meta.is_object() || !meta.contains("split") || !meta["split"].is_object() || !meta["split"].contains("val") ||
      !meta["split"]["val"].is_array())
    throw UserError("the model's metadata names no held-out demonstrations (split.val)");
  const std::vector<std::string>& movements = header.movement_names;
  ModelStarts starts(movements.size());
  for (const nlohmann::json& n : meta["split"]["val"]) {
    if (!n.is_string()) throw UserError("split.val holds a value that is not a demonstration name");
    const std::string name = n.get<std::string>();
    const auto cut = name.rfind('_');
    const auto it = cut == std::string::npos ? movements.end()
                                             : std::find(movements.begin(), movements.end(), name.substr(0, cut));
    if (it == movements.end())
      throw UserError("split.val names '" + name + "', which is not <movement>_<index> of the model's movements");
    const fs::path dir = fs::path(data_dir) / name;
    const std::vector<RetargetRow> rows = readRetargetCsv((dir / "retarget.csv").string());
    if (rows.empty()) throw UserError((dir / "retarget.csv").string() + ": no rows");
    ModelStart s;
    s.name = name;
    s.q = rows.front().result.q_r;
    s.ticks = gridRows(dir / "features.csv");
    if (s.ticks < 1 || s.ticks > kMaxStartTicks)
      throw UserError((dir / "features.csv").string() + ": " + std::to_string(s.ticks) + " rows, expected 1.." +
                      std::to_string(kMaxStartTicks));
    starts[static_cast<std::size_t>(it - movements.begin())].push_back(s);
  }
  return starts;
}

ModelStarts addModelStarts(const ModelFile& model, const std::string& data_dir, const std::string& out) {
  const ModelHeader& h = model.header;
  const nlohmann::json meta = nlohmann::json::parse(h.metadata_json, nullptr, /*allow_exceptions=*/false);
  if (meta.is_object() && meta.contains("data") && meta["data"].is_object() && meta["data"].contains("fingerprint") &&
      meta["data"]["fingerprint"].is_string()) {
    // The starts must be those of the demonstrations the model held out, as it saw them.
    const std::string want = meta["data"]["fingerprint"].get<std::string>();
    const std::string have = hex64(dataFingerprint(loadPolicyData(data_dir)));
    if (have != want)
      throw UserError(data_dir + " has data fingerprint " + have + ", the model was trained on " + want +
                      ": give the model's own data set (toolchain/nao train data makes it)");
  }
  const ModelStarts starts = heldOutStarts(h, data_dir);
  ModelHeader header = h;
  header.metadata_json = withModelStarts(h.metadata_json, h.movement_names, starts);
  std::vector<std::vector<float>> tensors;
  tensors.reserve(model.tensors.size());
  for (std::size_t i = 0; i < model.tensors.size(); ++i) {
    const float* f = model.data(i);
    tensors.emplace_back(f, f + model.tensors[i].spec.count());
  }
  writeModelFile(out, header, tensors);
  return starts;
}

NAO_REGISTER_COMMAND(model_starts, setup)

}  // namespace nao::tools
