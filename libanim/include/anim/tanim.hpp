#pragma once
// The native binary animation format (.tanim), specified in docs/tanim-format.md.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"

namespace anim {

std::vector<uint8_t> encodeTanim(const Animation& animation);
// Validates everything (magic, version, counts against the byte size, checksum, indices, times,
// finite coordinates) before building the animation; throws tsah::FileError naming `file`.
Animation decodeTanim(std::span<const uint8_t> bytes, const std::string& file);

// Atomic write (temporary file + rename).
void saveTanim(const Animation& animation, const std::string& path);
Animation loadTanim(const std::string& path);

}  // namespace anim
