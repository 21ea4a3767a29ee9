// Calibration files in the toolchain: our JSON through the runtime's reader, and the
// OpenCV/Anipose-style TOML (toml++, which the runtime library does not link), each of whose
// camera tables is converted to JSON and checked by the runtime's cameraFromJson.
#include "nao/tools/calibration.hpp"

#include "nao/input_error.hpp"
#include "nao/text_guard.hpp"
#include "nao/tools/command.hpp"

#include <nlohmann/json.hpp>
#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>
#include <vector>

namespace nao::tools {
namespace {

using nlohmann::json;

json tomlToJson(const toml::node& node) {
  if (const auto* t = node.as_table()) {
    json out = json::object();
    for (const auto& [key, value] : *t) out[std::string(key.str())] = tomlToJson(value);
    return out;
  }
  if (const auto* a = node.as_array()) {
    json out = json::array();
    for (const toml::node& e : *a) out.push_back(tomlToJson(e));
    return out;
  }
  if (const auto* i = node.as_integer()) return json(i->get());
  if (const auto* f = node.as_floating_point()) return json(f->get());
  if (const auto* s = node.as_string()) return json(s->get());
  if (const auto* b = node.as_boolean()) return json(b->get());
  return json("<date/time>");
}

}  // namespace

CameraSet parseCalibrationJson(const std::string& text, const std::string& source) {
  try {
    return parseCameraSetJson(text, source);
  } catch (const InputError& e) {
    throw UserError(e.what());
  }
}

CameraSet parseCalibrationToml(const std::string& text, const std::string& source) {
  if (text.size() > kMaxTextBytes)
    throw UserError(source + ": not a usable calibration file: " + std::to_string(text.size()) + " bytes");
  toml::table doc;
  try {
    doc = toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    throw UserError(source + ":" + std::to_string(e.source().begin.line) + ":" + std::to_string(e.source().begin.column) +
                    ": calibration TOML does not parse: " + std::string(e.description()));
  } catch (const std::exception& e) {  // toml++ reports its own limits (nesting, size) as other errors
    std::string what = e.what();
    std::replace(what.begin(), what.end(), '\n', ' ');
    throw UserError(source + ": calibration TOML does not parse: " + what);
  }
  // Camera tables in file order: toml++ keeps tables sorted by key, the source line does not.
  struct Section {
    std::uint32_t line;
    std::string key;
    const toml::table* table;
  };
  std::vector<Section> sections;
  for (const auto& [key, value] : doc) {
    const toml::table* t = value.as_table();
    const std::string k(key.str());
    const bool named_camera = k.size() > 4 && k.compare(0, 4, "cam_") == 0 &&
                              std::all_of(k.begin() + 4, k.end(), [](char c) { return c >= '0' && c <= '9'; });
    if (t == nullptr) {
      if (named_camera) throw UserError(source + ": [" + k + "] must be a table of camera fields");
      continue;
    }
    if (named_camera || t->contains("matrix")) sections.push_back({t->source().begin.line, k, t});
  }
  if (sections.empty())
    throw UserError(source + ": no camera sections (expected [cam_0], [cam_1], ... with size, matrix, distortions, "
                             "rotation, translation)");
  std::stable_sort(sections.begin(), sections.end(), [](const Section& a, const Section& b) { return a.line < b.line; });
  CameraSet out;
  try {
    for (const Section& s : sections)
      out.push_back(cameraFromJson(tomlToJson(*s.table), source + ": camera [" + s.key + "]", s.key));
    checkDistinctCameras(out, source);
  } catch (const InputError& e) {
    throw UserError(e.what());
  }
  return out;
}

CameraSet readCalibration(const std::string& path) {
  const auto dot = path.find_last_of('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext != "json" && ext != "toml")
    throw UserError("calibration " + path + ": unknown file type, expected a .json or .toml file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw UserError("cannot open calibration file " + path);
  std::ostringstream text;
  text << in.rdbuf();
  return ext == "json" ? parseCalibrationJson(text.str(), path) : parseCalibrationToml(text.str(), path);
}

std::string formatCalibrationJson(const CameraSet& cameras) { return formatCameraSetJson(cameras); }

}  // namespace nao::tools
