#pragma once
// A frame file pattern with one printf-style number (walk_%04d.obj): parsed once, then matched
// against file names (reading a sequence) or formatted for a frame (writing one). Hand-written
// rather than std::regex or a printf format: a user's pattern never becomes a format string, and no
// regex template is instantiated in the library (a module built by another compiler would link
// against different instantiations of it).
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace anim::detail {

struct FramePattern {
  std::string prefix, suffix;  // literal text around the number ("%%" already read as '%')
  int width = 0;               // %4d, %04d: at least this many digits (0: %d)
  bool zeroPad = false;        // %04d pads with zeros; %4d with spaces when formatting

  // The frame number of `name` when it is prefix + digits + suffix (with at least `width` digits
  // for a zero-padded pattern); none otherwise, or when the number does not fit 64 bits.
  std::optional<uint64_t> match(std::string_view name) const;
  // The file name of frame `number`, as printf would write it.
  std::string format(uint64_t number) const;
};

// The longest width a pattern may ask for (%0Nd with N at most this).
inline constexpr int kMaxFramePatternWidth = 64;

// Parses `pattern`; the error (for the caller's one-line message) when it does not hold exactly one
// %d-style number (%d, %Nd, %0Nd) besides literal "%%".
struct FramePatternParse {
  std::optional<FramePattern> pattern;
  std::string error;
};
FramePatternParse parseFramePattern(std::string_view pattern);

}  // namespace anim::detail
