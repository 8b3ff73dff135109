#pragma once
// The C type definitions of `tsah export`'s header (tsah_scene.h), shared by the flat export
// (cmd_export.cpp) and the two-level export (two_level_export.cpp): the binary node and the Woop
// triangle, the wide layouts' node and packet, each with a size check that compiles as C11 and C++.
#include <cstdint>
#include <string>

namespace tsah::cli {

// TsahBvhNode (64 bytes), TsahFloat4, TsahWoopTriangle (48 bytes) and their size checks.
std::string binaryExportTypes();

// TSAH_WIDTH, TsahBvh<width>Node and TsahWoopPacket<width> and their size checks; width 4 or 8.
std::string wideExportTypes(uint32_t width);

// The Woop ray-triangle test on the rows of a TsahWoopTriangle, as C comment lines (" * ...").
std::string woopTestComment();

// A float as a C literal that reads back to the same float ("1.5f").
std::string cFloatLiteral(float v);

}  // namespace tsah::cli

#include <span>

namespace tsah::cli {

template <typename T>
std::span<const uint8_t> bytesOf(std::span<const T> values) {
  return {reinterpret_cast<const uint8_t*>(values.data()), values.size_bytes()};
}

// Creates the export folder `out` (tsah::cli::UsageError when it exists and is not a folder,
// tsah::Failure when it cannot be created).
void makeExportFolder(const std::string& out);

}  // namespace tsah::cli
