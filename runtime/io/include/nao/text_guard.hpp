// Checks run on a text file before a recursive parser sees it (at configure
// time). TinyXML (under urdfdom) recurses once per element and reads a UTF-8 sequence's
// length off its lead byte; nlohmann::json recurses in dump(), copy and compare. Hostile text
// could overflow the stack or make the parser read past the buffer: these bound what the
// parser gets. Each returns an empty string when the text is fine, else one line saying what
// is wrong (without the file name: the caller adds it).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace nao {

/// Largest text input any reader accepts (URDF, JSON, TOML, CSV): far above every real file.
inline constexpr std::size_t kMaxTextBytes = std::size_t{64} << 20;

/// Nesting accepted in JSON and XML inputs; every format of the project nests a few levels.
inline constexpr int kMaxTextNesting = 64;

/// Size above kMaxTextBytes, or '[' / '{' (outside strings) nested deeper than `max_depth`.
std::string jsonShapeProblem(std::string_view text, int max_depth = kMaxTextNesting);

/// Size above kMaxTextBytes, a NUL byte, invalid UTF-8 (including a sequence cut off by the
/// end of the text), or elements nested deeper than `max_depth`. The depth counted is an
/// upper bound of what an XML parser can reach: start tags minus end tags, with comments,
/// CDATA, <? ?> and <! > sections and quoted attribute values skipped.
std::string xmlShapeProblem(std::string_view text, int max_depth = kMaxTextNesting);

/// Empty if `text` is valid UTF-8 (no overlong forms, surrogates or code points above
/// U+10FFFF, no sequence cut short), else the byte offset and the problem.
std::string utf8Problem(std::string_view text);

}  // namespace nao
