#pragma once
// Pieces of the .tbvh reader and writer shared by the single-tree file (bvh_file.cpp) and the tree
// set container (tree_set.cpp). Internal to libtsah.
#include <array>
#include <string>

#include "tsah/base/binary_io.hpp"

namespace tsah::detail {

inline constexpr std::array<char, 8> kTbvhMagic = {'T', 'S', 'A', 'H', 'B', 'V', 'H', '\0'};

// Where a container's next tree image starts (TreeImagesFileParts): the next multiple of 16 bytes.
inline uint64_t align16(uint64_t x) { return (x + 15) & ~uint64_t(15); }

// A NUL-padded name field of kTbvhNameBytes: 0-15 printable ASCII characters. writeTbvhName throws
// tsah::ConfigError when the name does not fit; readTbvhName fails the reader on a malformed field.
void writeTbvhName(tsah::ByteWriter& w, const std::string& name, const char* what);
std::string readTbvhName(tsah::ByteReader& r, const char* what);

}  // namespace tsah::detail
