#include "tsah/render/image.hpp"

#include <cstdlib>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"

// stb's functions are compiled static into this file only, so no other module can clash with them.
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STBI_WRITE_NO_STDIO
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#define STBI_NO_STDIO
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
#include <stb_image.h>
#include <stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace tsah {

namespace {
void appendBytes(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<uint8_t>*>(context);
  const auto* p = static_cast<const uint8_t*>(data);
  out->insert(out->end(), p, p + size);
}
}  // namespace

std::vector<uint8_t> encodePng(const Image& image) {
  if (image.width == 0 || image.height == 0 || image.rgb.size() != std::size_t(image.width) * image.height * 3)
    throw tsah::DataError("cannot encode an empty or inconsistent image as PNG");
  std::vector<uint8_t> out;
  if (!stbi_write_png_to_func(appendBytes, &out, int(image.width), int(image.height), 3, image.rgb.data(),
                              int(image.width * 3)))
    throw tsah::Failure("PNG encoding failed");
  return out;
}

void savePng(const std::string& path, const Image& image) { tsah::writeFileAtomically(path, encodePng(image)); }

Image decodePng(std::span<const uint8_t> bytes, const std::string& file) {
  if (bytes.size() > std::size_t(1) << 30) throw tsah::FileError(file, "PNG file too large");
  int w = 0, h = 0, channels = 0;
  stbi_uc* data = stbi_load_from_memory(bytes.data(), int(bytes.size()), &w, &h, &channels, 3);
  if (!data) throw tsah::FileError(file, std::string("cannot decode PNG: ") + stbi_failure_reason());
  Image image(static_cast<uint32_t>(w), static_cast<uint32_t>(h));
  std::copy(data, data + image.rgb.size(), image.rgb.begin());
  stbi_image_free(data);
  return image;
}

Image loadPng(const std::string& path) { return decodePng(tsah::readFile(path, std::size_t(1) << 30), path); }

ImageDifference compareImages(const Image& a, const Image& b, uint32_t threshold) {
  if (a.width != b.width || a.height != b.height || a.rgb.size() != b.rgb.size())
    throw tsah::DataError("images differ in size: " + std::to_string(a.width) + "x" + std::to_string(a.height) +
                          " vs " + std::to_string(b.width) + "x" + std::to_string(b.height));
  ImageDifference d;
  if (a.rgb.empty()) return d;
  uint64_t sum = 0, above = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) {
    const uint32_t diff = uint32_t(std::abs(int(a.rgb[i]) - int(b.rgb[i])));
    sum += diff;
    d.maxAbs = std::max(d.maxAbs, diff);
    above += diff > threshold;
  }
  d.meanAbs = double(sum) / double(a.rgb.size());
  d.fractionAbove = double(above) / double(a.rgb.size());
  return d;
}

}  // namespace tsah
