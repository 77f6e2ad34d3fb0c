// Reading line-based text files (private to the library): a line's words with their offsets, so
// that a message can quote the line's own text, and whole-token numbers.
#pragma once

#include <charconv>
#include <string_view>
#include <system_error>
#include <vector>

namespace digitize {

// Separators of SplitTokens: '\r' is one so that CRLF files read the same.
inline constexpr std::string_view kSpaceTabCr = " \t\r";
inline constexpr std::string_view kAsciiSpace = " \t\r\v\f";

struct TextToken {
  std::string_view text;
  size_t begin = 0;  // offset in the line
};

// The runs of `line` between runs of `separators` (none of them '\n').
inline std::vector<TextToken> SplitTokens(std::string_view line, std::string_view separators) {
  std::vector<TextToken> tokens;
  size_t i = 0;
  const auto space = [&](char ch) { return separators.find(ch) != std::string_view::npos; };
  while (i < line.size()) {
    while (i < line.size() && space(line[i])) ++i;
    const size_t b = i;
    while (i < line.size() && !space(line[i])) ++i;
    if (i > b) tokens.push_back({line.substr(b, i - b), b});
  }
  return tokens;
}

// The whole of `token` as a number, by std::from_chars: "nan" and "inf" are accepted (check
// std::isfinite where they are not), a value beyond T is not; a leading '+' only where
// `plus_allowed`. `value` is unspecified when false is returned.
template <class T>
bool ParseWholeNumber(std::string_view token, T& value, bool plus_allowed = false) {
  if (plus_allowed && !token.empty() && token.front() == '+') token.remove_prefix(1);
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  return ec == std::errc() && end == token.data() + token.size();
}

}  // namespace digitize
