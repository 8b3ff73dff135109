// Quake II MD2 vertex-keyframe models. Layout (little-endian): a 68-byte header of 17 int32 after the
// magic "IDP2" (version 8, skin size, frame size, counts of skins, vertices, texture coordinates,
// triangles, GL commands and frames, then the offsets of each block and of the end); triangles are
// 3 uint16 vertex indices + 3 uint16 texture indices; each frame is a float scale[3], a float
// translate[3], a 16-byte name and one (x, y, z, normal) byte quadruple per vertex, the position being
// byte * scale + translate. Frame names ("run01", "run02", ...) group frames into clips.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include "anim/assimp_import.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"

namespace anim {

namespace {

constexpr double kMd2Fps = 10.0;  // Quake II steps its model animations at 10 Hz

struct Md2Header {
  int32_t version, skinWidth, skinHeight, frameSize, numSkins, numVertices, numTexCoords, numTriangles,
      numGlCommands, numFrames, offsetSkins, offsetTexCoords, offsetTriangles, offsetFrames, offsetGlCommands,
      offsetEnd;
};

struct Md2 {
  Md2Header h;
  std::span<const uint8_t> bytes;
  std::string file;

  // A block of `count` records of `size` bytes at `offset`, checked against the file.
  std::span<const uint8_t> block(int64_t offset, int64_t count, int64_t size, const char* what) const {
    if (offset < 0 || count < 0 || size <= 0 || offset > int64_t(bytes.size()) ||
        count > (int64_t(bytes.size()) - offset) / size)
      throw tsah::FileError(file, std::string(what) + " (" + std::to_string(count) + " x " + std::to_string(size) +
                                  " bytes at offset " + std::to_string(offset) + ") lies outside the " +
                                  std::to_string(bytes.size()) + "-byte file");
    return bytes.subspan(std::size_t(offset), std::size_t(count * size));
  }

  std::string frameName(int32_t f) const {
    const auto rec = block(int64_t(h.offsetFrames) + int64_t(f) * h.frameSize, 1, h.frameSize, "frame");
    const char* name = reinterpret_cast<const char*>(rec.data() + 24);
    return std::string(name, strnlen(name, 16));
  }
};

Md2 parse(std::span<const uint8_t> bytes, const std::string& file) {
  tsah::ByteReader in(bytes, file);
  char magic[4];
  std::memcpy(magic, in.bytes(4, "magic").data(), 4);
  if (std::memcmp(magic, "IDP2", 4) != 0) in.fail("not an MD2 file (magic is not IDP2)");
  Md2 m{{}, bytes, file};
  int32_t f[16];
  for (int32_t& field : f) field = in.read<int32_t>("header");
  m.h = {f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9], f[10], f[11], f[12], f[13], f[14], f[15]};
  const Md2Header& h = m.h;
  if (h.version != 8) throw tsah::FileError(file, "unsupported MD2 version " + std::to_string(h.version) + " (expected 8)");
  if (h.numVertices < 1 || h.numVertices > 65535)
    throw tsah::FileError(file, "vertex count " + std::to_string(h.numVertices) + " is out of range [1, 65535]");
  if (h.numTriangles < 1) throw tsah::FileError(file, "the model has no triangles");
  if (h.numFrames < 1) throw tsah::FileError(file, "the model has no frames");
  if (h.frameSize < 40 + 4 * int64_t(h.numVertices))
    throw tsah::FileError(file, "frame size " + std::to_string(h.frameSize) + " is too small for " +
                                std::to_string(h.numVertices) + " vertices");
  m.block(h.offsetTriangles, h.numTriangles, 12, "triangle block");
  m.block(h.offsetFrames, h.numFrames, h.frameSize, "frame block");
  return m;
}

std::string groupOf(const std::string& frameName) {
  std::size_t end = frameName.size();
  while (end > 0 && std::isdigit(static_cast<unsigned char>(frameName[end - 1]))) --end;
  return frameName.substr(0, end);
}

std::vector<std::string> clipsOf(const Md2& m) {
  std::vector<std::string> clips;
  for (int32_t f = 0; f < m.h.numFrames; ++f) {
    const std::string g = groupOf(m.frameName(f));
    if (std::find(clips.begin(), clips.end(), g) == clips.end()) clips.push_back(g);
  }
  return clips;
}

}  // namespace

std::vector<std::string> md2Clips(std::span<const uint8_t> bytes, const std::string& file) {
  return clipsOf(parse(bytes, file));
}

Animation decodeMd2(std::span<const uint8_t> bytes, const std::string& file, const LoadOptions& options) {
  const Md2 m = parse(bytes, file);
  const Md2Header& h = m.h;
  if (!(options.fps >= 0.0) || !std::isfinite(options.fps))
    throw tsah::FileError(file, "frame rate must be a finite number >= 0");
  const double fps = options.fps > 0.0 ? options.fps : kMd2Fps;

  // The frames to keep: all of them, or one clip chosen by name or index.
  std::vector<int32_t> frames;
  if (options.clip.empty()) {
    for (int32_t f = 0; f < h.numFrames; ++f) frames.push_back(f);
  } else {
    const std::vector<std::string> clips = clipsOf(m);
    std::string chosen;
    if (std::find(clips.begin(), clips.end(), options.clip) != clips.end()) {
      chosen = options.clip;
    } else if (std::all_of(options.clip.begin(), options.clip.end(), [](unsigned char c) { return std::isdigit(c); }) &&
               options.clip.size() < 10 && std::stoul(options.clip) < clips.size()) {
      chosen = clips[std::stoul(options.clip)];
    } else {
      std::string list;
      for (const auto& c : clips) list += (list.empty() ? "" : ", ") + c;
      throw tsah::FileError(file, "no clip '" + options.clip + "' (clips: " + list + ")");
    }
    for (int32_t f = 0; f < h.numFrames; ++f)
      if (groupOf(m.frameName(f)) == chosen) frames.push_back(f);
  }

  const auto tris = m.block(h.offsetTriangles, h.numTriangles, 12, "triangle block");
  std::vector<uint32_t> indices(std::size_t(h.numTriangles) * 3);
  for (int32_t t = 0; t < h.numTriangles; ++t)
    for (int c = 0; c < 3; ++c) {
      uint16_t v;
      std::memcpy(&v, tris.data() + 12 * std::size_t(t) + 2 * c, 2);
      if (v >= h.numVertices)
        throw tsah::FileError(file, "triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) +
                                    " but the model has " + std::to_string(h.numVertices) + " vertices");
      indices[3 * std::size_t(t) + c] = v;
    }

  const std::size_t perFrame = std::size_t(h.numVertices) * 3;
  std::vector<float> positions(perFrame * frames.size());
  std::vector<double> times(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const auto rec = m.block(int64_t(h.offsetFrames) + int64_t(frames[k]) * h.frameSize, 1, h.frameSize, "frame");
    float scale[3], translate[3];
    std::memcpy(scale, rec.data(), 12);
    std::memcpy(translate, rec.data() + 12, 12);
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(scale[a]) || !std::isfinite(translate[a]))
        throw tsah::FileError(file, "frame " + std::to_string(frames[k]) + " has a non-finite scale or translation");
    const uint8_t* v = rec.data() + 40;
    float* out = positions.data() + k * perFrame;
    for (int32_t i = 0; i < h.numVertices; ++i)
      for (int a = 0; a < 3; ++a) out[3 * std::size_t(i) + a] = float(v[4 * std::size_t(i) + a]) * scale[a] + translate[a];
    times[k] = double(k) / fps;
    if (options.progress) options.progress(k + 1, frames.size());
  }
  std::string name = std::filesystem::path(file).stem().string();
  return Animation(std::move(indices), uint32_t(h.numVertices), std::move(positions), std::move(times), name);
}

}  // namespace anim
