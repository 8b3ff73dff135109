#pragma once
// 8-bit RGB images and PNG files (through stb_image / stb_image_write).
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tsah {

struct Image {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> rgb;  // row-major, top row first, 3 bytes per pixel

  Image() = default;
  Image(uint32_t w, uint32_t h) : width(w), height(h), rgb(std::size_t(w) * h * 3, 0) {}
  uint8_t* pixel(uint32_t x, uint32_t y) { return rgb.data() + (std::size_t(y) * width + x) * 3; }
  const uint8_t* pixel(uint32_t x, uint32_t y) const { return rgb.data() + (std::size_t(y) * width + x) * 3; }
};

std::vector<uint8_t> encodePng(const Image& image);
// Atomic (temporary file + rename); throws tsah::Failure naming the path on failure.
void savePng(const std::string& path, const Image& image);
// Any PNG, converted to RGB; throws tsah::FileError naming the file.
Image decodePng(std::span<const uint8_t> bytes, const std::string& file);
Image loadPng(const std::string& path);

// Per-channel absolute differences between two images of the same size.
struct ImageDifference {
  double meanAbs = 0.0;        // mean over all channels, in 0..255
  uint32_t maxAbs = 0;
  double fractionAbove = 0.0;  // fraction of channels differing by more than the threshold
};
ImageDifference compareImages(const Image& a, const Image& b, uint32_t threshold = 16);

}  // namespace tsah
