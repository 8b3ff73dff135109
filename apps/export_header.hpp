#pragma once
// What `tsah export`'s two writers share (cmd_export.cpp for flat trees, two_level_export.cpp for
// two-level scenes): the C type definitions of the header (tsah_scene.h), the binary node and the
// Woop triangle, the wide layouts' node and packet, each with a size check that compiles as C11
// and C++; the Woop test's description; the output folder.
#include <cstdint>
#include <span>
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

template <typename T>
std::span<const uint8_t> bytesOf(std::span<const T> values) {
  return {reinterpret_cast<const uint8_t*>(values.data()), values.size_bytes()};
}

// Creates the export folder `out` (tsah::cli::UsageError when it exists and is not a folder,
// tsah::Failure when it cannot be created).
void makeExportFolder(const std::string& out);

}  // namespace tsah::cli
