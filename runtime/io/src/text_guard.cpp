#include "nao/text_guard.hpp"

namespace nao {
namespace {

std::string tooLarge(std::size_t n) {
  return "is " + std::to_string(n) + " bytes, more than the " + std::to_string(kMaxTextBytes >> 20) +
         " MiB any input of this kind may have";
}

std::string tooDeep(int max_depth, std::size_t at) {
  return "nests deeper than " + std::to_string(max_depth) + " levels (at byte " + std::to_string(at) + ")";
}

// Position just past the first occurrence of `end` at or after `from`, or npos.
std::size_t skipPast(std::string_view text, std::size_t from, std::string_view end) {
  const std::size_t at = text.find(end, from);
  return at == std::string_view::npos ? at : at + end.size();
}

}  // namespace

std::string jsonShapeProblem(std::string_view text, int max_depth) {
  if (text.size() > kMaxTextBytes) return tooLarge(text.size());
  int depth = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\')
        ++i;  // the escaped character cannot end the string
      else if (c == '"')
        in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return tooDeep(max_depth, i);
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return {};
}

std::string utf8Problem(std::string_view text) {
  const auto* p = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    if (c < 0x80) {
      ++i;
      continue;
    }
    std::size_t len = 0;
    unsigned lo = 0x80, hi = 0xBF;  // allowed range of the second byte
    if (c >= 0xC2 && c <= 0xDF) {
      len = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
      len = 3;
      if (c == 0xE0) lo = 0xA0;  // overlong
      if (c == 0xED) hi = 0x9F;  // surrogates
    } else if (c >= 0xF0 && c <= 0xF4) {
      len = 4;
      if (c == 0xF0) lo = 0x90;  // overlong
      if (c == 0xF4) hi = 0x8F;  // above U+10FFFF
    } else {
      return "is not valid UTF-8 (byte " + std::to_string(i) + ")";
    }
    if (n - i < len) return "is not valid UTF-8 (a multi-byte character is cut off by the end of the text)";
    if (p[i + 1] < lo || p[i + 1] > hi) return "is not valid UTF-8 (byte " + std::to_string(i + 1) + ")";
    for (std::size_t k = 2; k < len; ++k)
      if (p[i + k] < 0x80 || p[i + k] > 0xBF) return "is not valid UTF-8 (byte " + std::to_string(i + k) + ")";
    i += len;
  }
  return {};
}

std::string xmlShapeProblem(std::string_view text, int max_depth) {
  if (text.size() > kMaxTextBytes) return tooLarge(text.size());
  if (const std::size_t nul = text.find('\0'); nul != std::string_view::npos)
    return "holds a NUL byte (byte " + std::to_string(nul) + "), which XML does not allow";
  if (std::string problem = utf8Problem(text); !problem.empty()) return problem;
  // Skipped sections end where the most lenient reading ends them, so that no element an XML
  // parser could see is hidden from the count; where the text is malformed the parser stops
  // early, which only makes the count an overestimate.
  int depth = 0;
  std::size_t i = 0;
  while (i < text.size()) {
    const std::size_t lt = text.find('<', i);
    if (lt == std::string_view::npos) break;
    const std::string_view rest = text.substr(lt);
    if (rest.compare(0, 4, "<!--") == 0) {
      i = skipPast(text, lt + 4, "-->");
    } else if (rest.compare(0, 9, "<![CDATA[") == 0) {
      i = skipPast(text, lt + 9, "]]>");
    } else if (rest.compare(0, 2, "<?") == 0 || rest.compare(0, 2, "<!") == 0) {
      i = skipPast(text, lt + 2, ">");
    } else if (rest.compare(0, 2, "</") == 0) {
      if (depth > 0) --depth;
      i = skipPast(text, lt + 2, ">");
    } else {
      // A start tag: up to its '>' outside quoted attribute values; "/>" closes it at once.
      std::size_t k = lt + 1;
      char quote = 0;
      char last = 0;
      for (; k < text.size(); ++k) {
        const char c = text[k];
        if (quote != 0) {
          if (c == quote) quote = 0;
        } else if (c == '"' || c == '\'') {
          quote = c;
        } else if (c == '>') {
          break;
        }
        if (c != ' ' && c != '\t' && c != '\n' && c != '\r') last = c;
      }
      const bool self_closing = k < text.size() && last == '/';
      if (!self_closing && ++depth > max_depth) return tooDeep(max_depth, lt);
      i = k < text.size() ? k + 1 : k;
    }
  }
  return {};
}

}  // namespace nao
