#include "frame_pattern.hpp"

#include <cctype>

namespace anim::detail {

namespace {
bool isDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }
}  // namespace

FramePatternParse parseFramePattern(std::string_view pattern) {
  FramePattern out;
  bool sawNumber = false;
  for (std::size_t i = 0; i < pattern.size(); ++i) {
    const char c = pattern[i];
    std::string& literal = sawNumber ? out.suffix : out.prefix;
    if (c != '%') {
      literal += c;
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      literal += '%';
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    const bool zeroPad = j < pattern.size() && pattern[j] == '0';
    int width = 0;
    while (j < pattern.size() && isDigit(pattern[j])) {
      width = width * 10 + (pattern[j++] - '0');
      if (width > kMaxFramePatternWidth)
        return {std::nullopt, "the frame number's width is over " + std::to_string(kMaxFramePatternWidth)};
    }
    if (j >= pattern.size() || pattern[j] != 'd' || sawNumber)
      return {std::nullopt, "frame pattern must contain exactly one %d-style number (e.g. %04d)"};
    out.width = width;
    out.zeroPad = zeroPad && width > 0;
    sawNumber = true;
    i = j;
  }
  if (!sawNumber) return {std::nullopt, "frame pattern has no %d"};
  return {std::move(out), {}};
}

std::optional<uint64_t> FramePattern::match(std::string_view name) const {
  if (name.size() < prefix.size() + suffix.size() + 1) return std::nullopt;
  if (name.substr(0, prefix.size()) != prefix || name.substr(name.size() - suffix.size()) != suffix)
    return std::nullopt;
  const std::string_view digits = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
  if (zeroPad && digits.size() < std::size_t(width)) return std::nullopt;
  uint64_t number = 0;
  for (const char c : digits) {
    if (!isDigit(c)) return std::nullopt;
    const uint64_t d = uint64_t(c - '0');
    if (number > (UINT64_MAX - d) / 10) return std::nullopt;
    number = number * 10 + d;
  }
  return number;
}

std::string FramePattern::format(uint64_t number) const {
  std::string digits = std::to_string(number);
  if (digits.size() < std::size_t(width)) digits.insert(0, std::size_t(width) - digits.size(), zeroPad ? '0' : ' ');
  return prefix + digits + suffix;
}

}  // namespace anim::detail
