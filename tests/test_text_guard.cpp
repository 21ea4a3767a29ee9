// The checks run on text before a recursive parser sees it: nesting bounds that are
// never below what the parser would reach, and a UTF-8 check that refuses every sequence a
// lead-byte-trusting reader could follow past the end.
#include "nao/text_guard.hpp"

#include <doctest/doctest.h>

#include <string>

using nao::jsonShapeProblem;
using nao::utf8Problem;
using nao::xmlShapeProblem;

namespace {

std::string repeat(const std::string& s, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += s;
  return out;
}

}  // namespace

TEST_CASE("JSON nesting is counted outside strings only, up to the bound and not beyond") {
  CHECK(jsonShapeProblem(repeat("[", 64) + repeat("]", 64)).empty());
  CHECK(jsonShapeProblem(repeat("[", 65) + repeat("]", 65)) == "nests deeper than 64 levels (at byte 64)");
  CHECK(jsonShapeProblem(repeat("{\"a\":", 65)).rfind("nests deeper than 64", 0) == 0);
  // Brackets inside strings, escaped quotes included, are text.
  CHECK(jsonShapeProblem("[\"" + repeat("[", 1000) + "\\\"" + repeat("{", 1000) + "\"]").empty());
  // Closing brackets free their level: a long flat sequence of arrays is fine.
  CHECK(jsonShapeProblem(repeat("[[1],[2]],", 10000)).empty());
  CHECK(jsonShapeProblem("[1, 2]", 1).empty());
  CHECK_FALSE(jsonShapeProblem("[[1]]", 1).empty());
}

TEST_CASE("XML nesting counts start tags against end tags; comments, CDATA and self-closing tags are not levels") {
  CHECK(xmlShapeProblem("<robot>" + repeat("<a>", 63) + repeat("</a>", 63) + "</robot>").empty());
  CHECK(xmlShapeProblem(repeat("<a>", 65)) == "nests deeper than 64 levels (at byte 192)");
  CHECK(xmlShapeProblem("<r>" + repeat("<a x=\"1\"/>", 1000) + "</r>").empty());
  CHECK(xmlShapeProblem("<r><!--" + repeat("<a>", 1000) + "--></r>").empty());
  CHECK(xmlShapeProblem("<r><![CDATA[" + repeat("<a>", 1000) + "]]></r>").empty());
  // A '>' or '/' inside a quoted attribute value neither ends nor closes the tag.
  CHECK_FALSE(xmlShapeProblem(repeat("<a x=\"/>\">", 65)).empty());
  // An unterminated comment hides nothing the parser would read as elements.
  CHECK(xmlShapeProblem("<r><!-- never closed " + repeat("<a>", 1000)).empty());
  // A '<?' or '<!' section ends at the first '>' (the most lenient reading).
  CHECK_FALSE(xmlShapeProblem("<?xml x='?>'>" + repeat("<a>", 65)).empty());
}

TEST_CASE("XML text must be NUL-free, valid UTF-8 and not absurdly large") {
  CHECK(xmlShapeProblem(std::string("<a>\0</a>", 8)) == "holds a NUL byte (byte 3), which XML does not allow");
  CHECK(xmlShapeProblem("<robot name=\"\xF2") ==
        "is not valid UTF-8 (a multi-byte character is cut off by the end of the text)");
  CHECK(xmlShapeProblem(std::string(nao::kMaxTextBytes + 1, ' ')).rfind("is 67108865 bytes", 0) == 0);
  CHECK(jsonShapeProblem(std::string(nao::kMaxTextBytes + 1, ' ')).rfind("is 67108865 bytes", 0) == 0);
}

TEST_CASE("utf8Problem accepts every well-formed sequence and refuses malformed ones") {
  CHECK(utf8Problem("plain ASCII").empty());
  CHECK(utf8Problem("caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x98\x80 \xF4\x8F\xBF\xBF").empty());  // é € 😀 U+10FFFF
  CHECK(utf8Problem("\x80") == "is not valid UTF-8 (byte 0)");             // continuation byte first
  CHECK(utf8Problem("a\xC0\x80") == "is not valid UTF-8 (byte 1)");        // overlong NUL
  CHECK(utf8Problem("\xE0\x80\x80") == "is not valid UTF-8 (byte 1)");     // overlong 3-byte
  CHECK(utf8Problem("\xED\xA0\x80") == "is not valid UTF-8 (byte 1)");     // surrogate U+D800
  CHECK(utf8Problem("\xF4\x90\x80\x80") == "is not valid UTF-8 (byte 1)"); // above U+10FFFF
  CHECK(utf8Problem("\xF5\x80\x80\x80") == "is not valid UTF-8 (byte 0)");
  CHECK(utf8Problem("\xE2\x82") == "is not valid UTF-8 (a multi-byte character is cut off by the end of the text)");
  CHECK(utf8Problem("\xE2\x28\xA1") == "is not valid UTF-8 (byte 1)");
  CHECK(utf8Problem("\xF0\x9F\x98\x28") == "is not valid UTF-8 (byte 3)");
}
