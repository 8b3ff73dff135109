#include "tsah/io/bvh_file.hpp"

#include <array>
#include <cmath>
#include <cstring>

#include "tsah/base/assert.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"
#include "io/tbvh_io.hpp"

namespace tsah {

namespace {

constexpr uint32_t kNodeBytes = sizeof(GpuBvhNode);
constexpr std::size_t kReservedWords = 4;  // header padding up to kTbvhHeaderBytes, written as 0

static_assert(sizeof(Aabb) == 24);

}  // namespace

namespace detail {

void writeTbvhName(tsah::ByteWriter& w, const std::string& name, const char* what) {
  if (name.size() >= kTbvhNameBytes)
    throw tsah::ConfigError(std::string(".tbvh ") + what + " name '" + name + "' is longer than " +
                            std::to_string(kTbvhNameBytes - 1) + " characters");
  for (char c : name)
    if (c < 0x20 || c > 0x7e) throw tsah::ConfigError(std::string(".tbvh ") + what + " name must be printable ASCII");
  std::array<char, kTbvhNameBytes> field{};
  std::memcpy(field.data(), name.data(), name.size());
  w.write(field);
}

std::string readTbvhName(tsah::ByteReader& r, const char* what) {
  const auto field = r.read<std::array<char, kTbvhNameBytes>>(what);
  std::size_t len = 0;
  while (len < field.size() && field[len] != '\0') ++len;
  if (len == field.size()) r.fail(std::string(what) + " is not NUL-terminated");
  for (std::size_t i = 0; i < len; ++i)
    if (field[i] < 0x20 || field[i] > 0x7e) r.fail(std::string(what) + " is not printable ASCII");
  for (std::size_t i = len; i < field.size(); ++i)
    if (field[i] != '\0') r.fail(std::string(what) + " has bytes after its terminating NUL");
  return std::string(field.data(), len);
}

}  // namespace detail

using detail::kTbvhMagic;
using detail::readTbvhName;
using detail::writeTbvhName;

uint32_t topologyHash(std::span<const uint32_t> indices) {
  return tsah::crc32(indices.data(), indices.size_bytes());
}

namespace {

template <typename T>
std::span<const uint8_t> bytesOf(const std::vector<T>& v) {
  return {reinterpret_cast<const uint8_t*>(v.data()), v.size() * sizeof(T)};
}

constexpr std::array<uint8_t, 16> kZeros{};  // the padding before each tree image of a container

}  // namespace

std::array<std::span<const uint8_t>, 5> BvhFileParts::parts() const {
  return {std::span<const uint8_t>(header), bytesOf(flat->nodes), bytesOf(flat->rootBoxes), bytesOf(flat->triIndex),
          std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(&crc), sizeof crc)};
}

uint64_t BvhFileParts::size() const {
  uint64_t bytes = 0;
  for (const auto& part : parts()) bytes += part.size();
  return bytes;
}

uint32_t BvhFileParts::wholeCrc() const { return tsah::crc32(&crc, sizeof crc, crc); }

void TreeImagesFileParts::seal() {
  crc = tsah::crc32(tables.data(), tables.size());
  uint64_t offset = tables.size();
  for (const BvhFileParts& image : images) {
    crc = tsah::crc32(kZeros.data(), detail::align16(offset) - offset, crc);
    crc = tsah::crc32Combine(crc, image.wholeCrc(), image.size());
    offset = detail::align16(offset) + image.size();
  }
}

std::vector<std::span<const uint8_t>> TreeImagesFileParts::parts() const {
  std::vector<std::span<const uint8_t>> out{std::span<const uint8_t>(tables)};
  uint64_t offset = tables.size();
  for (const BvhFileParts& image : images) {
    out.push_back(std::span<const uint8_t>(kZeros.data(), detail::align16(offset) - offset));
    for (const std::span<const uint8_t> part : image.parts()) out.push_back(part);
    offset = detail::align16(offset) + image.size();
  }
  out.push_back(std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(&crc), sizeof crc));
  return out;
}

std::vector<uint8_t> TreeImagesFileParts::bytes() const { return joinedBytes(parts()); }

BvhFileParts bvhFileParts(const FlatBvh& flat, const BvhBuildInfo& info) {
  BvhFileParts out;
  out.flat = &flat;
  if (info.triangleCount != 0 && info.triangleCount != flat.triangleCount())
    throw tsah::DataError(".tbvh build info says " + std::to_string(info.triangleCount) +
                          " triangles, the tree holds " + std::to_string(flat.triangleCount()));

  tsah::ByteWriter w;
  w.buffer().reserve(kTbvhHeaderBytes);
  w.write(kTbvhMagic);
  w.write(kTbvhVersion);
  w.write(kTbvhLayoutAilaLaine64);
  w.write(kTbvhHeaderBytes);
  w.write(kNodeBytes);
  w.write(flat.triangleCount());
  w.write(info.vertexCount);
  w.write(flat.interiorCount);
  w.write(flat.leafCount);
  w.write(flat.frameCount);
  w.write(flat.rootRef);
  w.write(flat.rootCount);
  w.write(info.topologyHash);
  w.write(info.objective.cost.ct);
  w.write(info.objective.cost.ci);
  w.write(static_cast<int32_t>(info.objective.k));
  w.write(info.representativeFrames);
  w.write(info.seed);
  w.write(info.objective.maxLeafSize);
  w.write(flat.depth);
  w.write(info.buildSeconds);
  w.write(info.timeStart);
  w.write(info.timeEnd);
  writeTbvhName(w, info.method, "method");
  writeTbvhName(w, info.selection, "selection");
  for (std::size_t i = 0; i < kReservedWords; ++i) w.write(uint32_t{0});
  TSAH_ASSERT(w.buffer().size() == kTbvhHeaderBytes, ".tbvh header size mismatch");
  out.header = std::move(w.buffer());
  const auto parts = out.parts();
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) out.crc = tsah::crc32(parts[i].data(), parts[i].size(), out.crc);
  return out;
}

std::vector<uint8_t> encodeBvhFile(const Bvh& bvh, const BvhBuildInfo& info) {
  const FlatBvh flat = flattenBvh(bvh);
  return joinedBytes(bvhFileParts(flat, info).parts());
}

FlatBvh decodeFlatBvhFile(std::span<const uint8_t> bytes, const std::string& file, BvhBuildInfo* infoOut) {
  tsah::ByteReader r(bytes, file);
  const auto magic = r.read<std::array<char, 8>>("magic");
  if (magic != kTbvhMagic) r.fail("not a .tbvh file (bad magic)");
  const auto version = r.read<uint32_t>("version");
  if (version == 2)
    r.fail("holds a tree set (.tbvh version 2): read it with the tree-set reader (tsah::decodeTreeSetFile)");
  if (version == 3)
    r.fail("holds a two-level scene (.tbvh version 3): read it with its scene (tsah::loadTwoLevelSceneFile)");
  if (version != kTbvhVersion)
    r.fail("unsupported .tbvh version " + std::to_string(version) + " (this reader knows " +
           std::to_string(kTbvhVersion) + ")");
  const auto layout = r.read<uint32_t>("layout");
  if (layout != kTbvhLayoutAilaLaine64) r.fail("unknown node layout " + std::to_string(layout));
  if (r.read<uint32_t>("header size") != kTbvhHeaderBytes) r.fail("header size is not " + std::to_string(kTbvhHeaderBytes));
  if (r.read<uint32_t>("node size") != kNodeBytes) r.fail("node size is not " + std::to_string(kNodeBytes));

  BvhBuildInfo info;
  FlatBvh flat;
  const auto triangleCount = r.read<uint32_t>("triangle count");
  info.triangleCount = triangleCount;
  info.vertexCount = r.read<uint32_t>("vertex count");
  flat.interiorCount = r.read<uint32_t>("interior node count");
  flat.leafCount = r.read<uint32_t>("leaf count");
  flat.frameCount = r.read<uint32_t>("frame count");
  flat.rootRef = r.read<int32_t>("root reference");
  flat.rootCount = r.read<uint32_t>("root count");
  info.topologyHash = r.read<uint32_t>("topology hash");
  info.objective.cost.ct = r.read<float>("cT");
  info.objective.cost.ci = r.read<float>("cI");
  info.objective.k = r.read<int32_t>("k");
  info.representativeFrames = r.read<uint32_t>("representative frames");
  info.seed = r.read<uint64_t>("seed");
  info.objective.maxLeafSize = r.read<uint32_t>("max leaf size");
  flat.depth = r.read<uint32_t>("depth");
  info.buildSeconds = r.read<double>("build seconds");
  info.timeStart = r.read<double>("time start");
  info.timeEnd = r.read<double>("time end");
  info.method = readTbvhName(r, "method");
  info.selection = readTbvhName(r, "selection");
  for (std::size_t i = 0; i < kReservedWords; ++i)
    if (r.read<uint32_t>("reserved") != 0) r.fail("reserved header words must be 0");

  // Counts against the byte count before any allocation (64-bit arithmetic cannot overflow:
  // every factor is checked against the bytes left first).
  if (triangleCount == 0) r.fail("the tree holds no triangles");
  if (triangleCount > kMaxGpuTriangles) r.fail("triangle count " + std::to_string(triangleCount) + " too large");
  if (flat.frameCount == 0) r.fail("frame count is 0");
  const uint64_t left = r.remaining();
  const uint64_t perFrame = uint64_t(flat.interiorCount) * kNodeBytes + sizeof(Aabb);
  const uint64_t fixed = uint64_t(triangleCount) * 4 + 4;
  if (fixed > left || flat.frameCount > (left - fixed) / perFrame ||
      uint64_t(flat.frameCount) * perFrame + fixed != left)
    r.fail("file size " + std::to_string(bytes.size()) + " does not match the counts in the header (" +
           std::to_string(triangleCount) + " triangles, " + std::to_string(flat.interiorCount) +
           " interior nodes, " + std::to_string(flat.frameCount) + " frames)");
  const std::size_t crcOffset = bytes.size() - 4;
  uint32_t storedCrc;
  std::memcpy(&storedCrc, bytes.data() + crcOffset, 4);
  if (tsah::crc32(bytes.data(), crcOffset) != storedCrc) r.fail("checksum mismatch (the file is corrupt)");

  if (!std::isfinite(info.objective.cost.ct) || !std::isfinite(info.objective.cost.ci) || info.objective.cost.ct < 0 || info.objective.cost.ci < 0)
    r.fail("cost constants must be finite and non-negative");
  if (!std::isfinite(info.timeStart) || !std::isfinite(info.timeEnd) || info.timeEnd < info.timeStart)
    r.fail("time range must be finite and ordered");
  if (!std::isfinite(info.buildSeconds) || info.buildSeconds < 0) r.fail("build time must be finite and >= 0");

  r.readArray(flat.nodes, std::size_t(flat.frameCount) * flat.interiorCount, "nodes");
  r.readArray(flat.rootBoxes, flat.frameCount, "root boxes");
  r.readArray(flat.triIndex, triangleCount, "triangle index array");
  if (auto problem = validateFlatBvh(flat)) throw tsah::FileError(file, *problem);
  if (flat.depth > kMaxBvhDepth)  // tsah never writes one; the runtimes' stacks could not trace it
    throw tsah::FileError(file, "tree depth " + std::to_string(flat.depth) + " exceeds the limit of " +
                                    std::to_string(kMaxBvhDepth) + " levels");
  if (infoOut) *infoOut = std::move(info);
  return flat;
}

BvhFile decodeBvhFile(std::span<const uint8_t> bytes, const std::string& file) {
  BvhFile result;
  const FlatBvh flat = decodeFlatBvhFile(bytes, file, &result.info);
  result.bvh = unflattenBvh(flat);
  return result;
}

void saveBvhFile(const std::string& path, const Bvh& bvh, const BvhBuildInfo& info) {
  tsah::requireExtension(path, ".tbvh", "tree");
  const FlatBvh flat = flattenBvh(bvh);
  const BvhFileParts encoded = bvhFileParts(flat, info);
  const auto parts = encoded.parts();
  tsah::writeFileAtomically(path, std::span<const std::span<const uint8_t>>(parts));
}

BvhFile loadBvhFile(const std::string& path) { return decodeBvhFile(tsah::readFile(path), path); }

}  // namespace tsah
