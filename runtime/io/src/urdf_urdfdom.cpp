// The default URDF reader: urdfdom's own parser (urdf_reader.hpp). Not compiled in
// NAO_URDF_READER=tinyxml builds (preset nao), which have no liburdfdom to link statically.
#include "nao/urdf_reader.hpp"

#include <console_bridge/console.h>
#include <urdf_parser/urdf_parser.h>

namespace nao {
namespace {

// urdfdom reports why it rejects a file only through console_bridge; collect those lines so
// the exception can carry them instead of letting them scroll past on stderr.
class CollectErrors : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR) {
      if (!text_.empty()) text_ += "; ";
      text_ += text;
    }
  }
  const std::string& text() const { return text_; }

 private:
  std::string text_;
};

}  // namespace

std::shared_ptr<urdf::ModelInterface> parseUrdfUrdfdom(const std::string& urdf_xml, std::string& reason) {
  CollectErrors errors;
  console_bridge::useOutputHandler(&errors);
  std::shared_ptr<urdf::ModelInterface> urdf = urdf::parseURDF(urdf_xml);
  console_bridge::restorePreviousOutputHandler();
  reason = urdf ? std::string() : errors.text();
  return urdf;
}

}  // namespace nao
