// PC2 and MDD point caches: the byte codecs (layouts in point_cache.hpp and docs/point-caches.md).
// Pairing a cache with a mesh lives in point_cache_import.cpp, so this file needs no mesh reader.
#include "anim/point_cache.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"

namespace anim {

namespace {

namespace fs = std::filesystem;

constexpr std::array<char, 12> kPc2Signature{'P', 'O', 'I', 'N', 'T', 'C', 'A', 'C', 'H', 'E', '2', '\0'};
constexpr int32_t kPc2Version = 1;
constexpr std::size_t kPointBytes = 3 * sizeof(float);
// PC2 sample times must sit on a uniform grid; the relative tolerance of that check.
constexpr double kUniformTolerance = 1e-4;

uint32_t swapBytes(uint32_t v) { return __builtin_bswap32(v); }

int32_t readBigInt32(tsah::ByteReader& in, const char* what) {
  return std::bit_cast<int32_t>(swapBytes(in.read<uint32_t>(what)));
}

// Fails unless `count` (a header field) lies in [1, 2^31).
uint32_t checkedCount(int32_t count, const std::string& file, const char* what) {
  if (count < 1) throw tsah::FileError(file, std::string(what) + " " + std::to_string(count) + " is absurd (must be at least 1)");
  return uint32_t(count);
}

// The position floats of a cache: `frames` blocks of `points` xyz triples, no more and no fewer
// bytes than that left in the reader (checked before allocating). Big-endian floats are swapped.
std::vector<float> readPositions(tsah::ByteReader& in, uint32_t frames, uint32_t points, bool bigEndian) {
  const uint64_t blockBytes = uint64_t(points) * kPointBytes;
  const uint64_t left = in.remaining();
  const std::string promised = std::to_string(frames) + " frames of " + std::to_string(points) + " points (" +
                               std::to_string(frames) + " x " + std::to_string(blockBytes) + " bytes)";
  if (left / blockBytes < frames)
    in.fail("truncated: the header promises " + promised + ", " + std::to_string(left) + " bytes are left");
  if (left != uint64_t(frames) * blockBytes)  // no overflow: frames * blockBytes <= left here
    in.fail(std::to_string(left - uint64_t(frames) * blockBytes) + " bytes follow the " + promised +
            " the header promises (a wrong header, or not a point cache)");
  std::vector<float> positions;
  in.readArray(positions, std::size_t(frames) * points * 3, "positions");
  if (bigEndian)
    for (float& v : positions) v = std::bit_cast<float>(swapBytes(std::bit_cast<uint32_t>(v)));
  return positions;
}

// Finite and within kMaxCoordinate, as every importer checks (the Animation would refuse it later,
// without naming this file).
void checkCoordinates(const PointCache& cache, const std::string& file) {
  const std::size_t perFrame = std::size_t(cache.pointCount) * 3;
  const std::size_t i = firstBadCoordinate(cache.positions);
  if (i < cache.positions.size())
    throw tsah::FileError(file, "frame " + std::to_string(i / perFrame) + ", point " + std::to_string((i % perFrame) / 3) +
                                " " + describeBadCoordinate(cache.positions[i]));
}

void checkTimes(const std::vector<double>& times, const std::string& file) {
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (!std::isfinite(times[i])) throw tsah::FileError(file, "frame " + std::to_string(i) + " has a non-finite time");
    if (i > 0 && !(times[i] > times[i - 1]))
      throw tsah::FileError(file, "frame " + std::to_string(i) + " time " + std::to_string(times[i]) +
                                  " is not after the previous frame's (" + std::to_string(times[i - 1]) + ")");
  }
}

std::span<const uint8_t> asBytes(const std::vector<uint8_t>& v) { return v; }

bool fitsFloat32(double v) { return std::fabs(v) <= double(std::numeric_limits<float>::max()); }

std::string formatNumber(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", v);
  return text;
}

void checkEncodable(const Animation& a, const char* format) {
  if (a.keyframeCount() == 0 || a.vertexCount() == 0)
    throw tsah::DataError(a.name() + ": nothing to write as " + format + " (no keyframes or no vertices)");
  if (a.keyframeCount() > uint32_t(INT32_MAX) || a.vertexCount() > uint32_t(INT32_MAX))
    throw tsah::DataError(a.name() + ": too many keyframes or vertices for " + format);
  // Both formats store times as float32: a time beyond its range would be written as infinity,
  // which every reader refuses. (Coordinates are float32 already and bounded by kMaxCoordinate.)
  for (std::size_t k = 0; k < a.times().size(); ++k)
    if (!fitsFloat32(a.times()[k]))
      throw tsah::DataError(a.name() + ": keyframe " + std::to_string(k) + " at time " + formatNumber(a.times()[k]) +
                            " does not fit the float32 times of the " + format + " format");
}

void writeBigEndian(tsah::ByteWriter& out, uint32_t bits) { out.write(swapBytes(bits)); }

}  // namespace

std::optional<PointCacheFormat> pointCacheFormat(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".pc2") return PointCacheFormat::Pc2;
  if (ext == ".mdd") return PointCacheFormat::Mdd;
  return std::nullopt;
}

PointCache decodePc2(std::span<const uint8_t> bytes, const std::string& file) {
  tsah::ByteReader in(bytes, file);
  std::array<char, 12> signature;
  std::memcpy(signature.data(), in.bytes(signature.size(), "PC2 signature").data(), signature.size());
  if (signature != kPc2Signature) throw tsah::FileError(file, "not a PC2 file (the signature is not POINTCACHE2)");
  const int32_t version = in.read<int32_t>("PC2 version");
  if (version != kPc2Version)
    throw tsah::FileError(file, "unsupported PC2 version " + std::to_string(version) + " (expected 1)");
  PointCache cache;
  cache.pointCount = checkedCount(in.read<int32_t>("point count"), file, "point count");
  const float start = in.read<float>("start frame");
  const float rate = in.read<float>("sample rate");
  const uint32_t samples = checkedCount(in.read<int32_t>("sample count"), file, "sample count");
  if (!std::isfinite(start) || !std::isfinite(rate) || (samples > 1 && !(rate > 0.0f)))
    throw tsah::FileError(file, "start frame " + std::to_string(start) + " and sample rate " + std::to_string(rate) +
                                " do not give increasing sample times (the rate must be a finite number > 0)");
  cache.positions = readPositions(in, samples, cache.pointCount, false);
  cache.times.resize(samples);
  for (uint32_t i = 0; i < samples; ++i) cache.times[i] = double(start) + double(i) * double(rate);
  checkTimes(cache.times, file);
  checkCoordinates(cache, file);
  return cache;
}

PointCache decodeMdd(std::span<const uint8_t> bytes, const std::string& file) {
  tsah::ByteReader in(bytes, file);
  const uint32_t frames = checkedCount(readBigInt32(in, "frame count"), file, "frame count");
  PointCache cache;
  cache.pointCount = checkedCount(readBigInt32(in, "point count"), file, "point count");
  std::vector<uint32_t> timeBits;
  in.readArray(timeBits, frames, "frame times");  // checked against the bytes left before allocating
  cache.times.resize(frames);
  for (uint32_t i = 0; i < frames; ++i) cache.times[i] = double(std::bit_cast<float>(swapBytes(timeBits[i])));
  checkTimes(cache.times, file);
  // Blender's exporter writes the rest pose before the frames it counts: exactly one block more.
  const uint64_t blockBytes = uint64_t(cache.pointCount) * kPointBytes;
  if (in.remaining() % blockBytes == 0 && in.remaining() / blockBytes == uint64_t(frames) + 1) {
    in.bytes(std::size_t(blockBytes), "rest frame");
    cache.skippedRestFrame = true;
  }
  cache.positions = readPositions(in, frames, cache.pointCount, true);
  checkCoordinates(cache, file);
  return cache;
}

PointCache decodePointCache(std::span<const uint8_t> bytes, const std::string& file, PointCacheFormat format) {
  return format == PointCacheFormat::Pc2 ? decodePc2(bytes, file) : decodeMdd(bytes, file);
}

std::vector<uint8_t> encodePc2(const Animation& a) {
  checkEncodable(a, "PC2");
  const auto times = a.times();
  const std::size_t n = times.size();
  const float start = float(times[0]);
  const double step = n > 1 ? (times[n - 1] - times[0]) / double(n - 1) : 1.0;
  if (!fitsFloat32(step))
    throw tsah::DataError(a.name() + ": the step " + formatNumber(step) +
                          " between keyframes does not fit the float32 sample rate of the PC2 format");
  const float rate = float(step);
  for (std::size_t i = 0; i < n; ++i) {
    const double expected = double(start) + double(i) * double(rate);
    if (std::fabs(times[i] - expected) > kUniformTolerance * std::max(double(rate), std::fabs(expected)))
      throw tsah::DataError(a.name() + ": keyframe " + std::to_string(i) + " at time " + std::to_string(times[i]) +
                            " is off the uniform grid a PC2 file stores (start " + std::to_string(start) + ", step " +
                            std::to_string(rate) +
                            "); resample with --frames N, or write .mdd, which keeps every time");
  }
  tsah::ByteWriter out;
  out.append(kPc2Signature.data(), kPc2Signature.size());
  out.write(kPc2Version);
  out.write(int32_t(a.vertexCount()));
  out.write(start);
  out.write(rate);
  out.write(int32_t(n));
  const std::vector<float> positions = a.allPositions();
  out.writeArray(std::span<const float>(positions));
  return std::move(out.buffer());
}

std::vector<uint8_t> encodeMdd(const Animation& a) {
  checkEncodable(a, "MDD");
  tsah::ByteWriter out;
  writeBigEndian(out, a.keyframeCount());
  writeBigEndian(out, a.vertexCount());
  float previous = -INFINITY;
  for (uint32_t k = 0; k < a.keyframeCount(); ++k) {
    const float t = float(a.times()[k]);
    if (!(t > previous))
      throw tsah::DataError(a.name() + ": keyframe times " + std::to_string(a.times()[k - 1]) + " and " +
                            std::to_string(a.times()[k]) + " are equal in the float32 time table of an MDD file");
    previous = t;
    writeBigEndian(out, std::bit_cast<uint32_t>(t));
  }
  for (float v : a.allPositions()) writeBigEndian(out, std::bit_cast<uint32_t>(v));
  return std::move(out.buffer());
}

namespace {
std::vector<uint8_t> encodeFor(const Animation& animation, const std::string& path) {
  const auto format = pointCacheFormat(path);
  if (!format) throw tsah::ConfigError(path + ": a point cache file must end in .pc2 or .mdd");
  return *format == PointCacheFormat::Pc2 ? encodePc2(animation) : encodeMdd(animation);
}
}  // namespace

void savePointCache(const Animation& animation, const std::string& path) {
  tsah::writeFileAtomically(path, asBytes(encodeFor(animation, path)));
}

void savePointCache(const Animation& animation, const std::string& path, tsah::AtomicFileSet& set) {
  set.write(path, asBytes(encodeFor(animation, path)));
}

}  // namespace anim
