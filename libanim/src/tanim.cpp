#include "anim/tanim.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"

namespace anim {

// Layout: see docs/tanim-format.md. All integers little-endian.
namespace {

constexpr std::array<char, 8> kMagic{'T', 'S', 'A', 'H', 'A', 'N', 'I', 'M'};
constexpr uint32_t kVersion = 2;  // 2: static vertices stored once; version 1 is still read
constexpr std::size_t kMaxName = 4096;
constexpr std::size_t kMaxCameraKeys = 1u << 20;

struct Header {
  std::array<char, 8> magic;
  uint32_t version;
  uint32_t flags;  // reserved, 0
  uint32_t vertexCount;
  uint32_t triangleCount;
  uint32_t keyframeCount;
  uint32_t cameraKeyCount;
  uint32_t nameBytes;
  uint32_t movingVertexCount;  // version 2: M (== V when every vertex moves); version 1: 0
  uint64_t payloadBytes;
  uint32_t payloadCrc;
  uint32_t reserved2[2];
  uint32_t headerCrc;  // CRC-32 of the 60 bytes before it
};
static_assert(sizeof(Header) == 64);

struct CameraRecord {
  double time;
  float eye[3], lookAt[3], up[3];
  float fovyDegrees;
};
static_assert(sizeof(CameraRecord) == 48);

constexpr std::size_t padTo8(std::size_t n) { return (n + 7) & ~std::size_t(7); }

// Vertices stored per keyframe: all of them in version 1, the moving ones in version 2.
uint32_t keyedVertices(const Header& h) { return h.version == 1 ? h.vertexCount : h.movingVertexCount; }
// Version 2 stores rest positions (V*3 f32) and moving ids (M u32) when some vertices are static.
bool hasStaticPart(const Header& h) { return h.version >= 2 && h.movingVertexCount < h.vertexCount; }

// Payload size for the given counts, or 0 when it would overflow 64 bits.
uint64_t payloadSize(const Header& h) {
  uint64_t positionBytes;
  if (__builtin_mul_overflow(uint64_t(h.keyframeCount) * keyedVertices(h), uint64_t(12), &positionBytes)) return 0;
  uint64_t size = padTo8(h.nameBytes) + uint64_t(h.keyframeCount) * 8 + uint64_t(h.triangleCount) * 12 +
                  uint64_t(h.cameraKeyCount) * 48;
  if (hasStaticPart(h)) size += uint64_t(h.vertexCount) * 12 + padTo8(uint64_t(h.movingVertexCount) * 4);
  if (__builtin_add_overflow(size, positionBytes, &size)) return 0;
  return size;
}

bool finite3(const std::array<float, 3>& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

// Every value finite and the times increasing: what the camera of `tsah trace` needs, refused here
// so that the message names this file and the key.
void checkCameraKeys(const std::vector<CameraKey>& keys, const std::string& file) {
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const CameraKey& k = keys[i];
    const char* bad = !std::isfinite(k.time)        ? "time"
                      : !finite3(k.eye)              ? "eye"
                      : !finite3(k.lookAt)           ? "look-at point"
                      : !finite3(k.up)               ? "up vector"
                      : !std::isfinite(k.fovyDegrees) ? "field of view"
                                                     : nullptr;
    if (bad) throw tsah::FileError(file, "camera key " + std::to_string(i) + " has a non-finite " + bad);
    if (i > 0 && !(k.time > keys[i - 1].time))
      throw tsah::FileError(file, "camera key " + std::to_string(i) + " time " + std::to_string(k.time) +
                                  " is not after the previous key's (" + std::to_string(keys[i - 1].time) + ")");
  }
}

bool isControl(char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }

}  // namespace

std::vector<uint8_t> encodeTanim(const Animation& a) {
  std::string name = a.name().substr(0, kMaxName);
  std::replace_if(name.begin(), name.end(), isControl, '_');  // readers refuse control characters
  Header h{};
  h.magic = kMagic;
  h.version = kVersion;
  h.vertexCount = a.vertexCount();
  h.triangleCount = a.triangleCount();
  h.keyframeCount = a.keyframeCount();
  h.movingVertexCount = a.movingVertexCount();
  h.cameraKeyCount = static_cast<uint32_t>(a.cameraPath().size());
  h.nameBytes = static_cast<uint32_t>(name.size());
  h.payloadBytes = payloadSize(h);

  tsah::ByteWriter payload;
  payload.append(name.data(), name.size());
  const uint64_t zero = 0;
  payload.append(&zero, padTo8(name.size()) - name.size());
  payload.writeArray(a.times());
  payload.writeArray(a.indices());
  if (hasStaticPart(h)) {
    payload.writeArray(a.restPositions());
    payload.writeArray(a.movingVertices());
    payload.append(&zero, padTo8(a.movingVertices().size_bytes()) - a.movingVertices().size_bytes());
  }
  payload.writeArray(a.motion());
  for (const CameraKey& k : a.cameraPath()) {
    CameraRecord r{};
    r.time = k.time;
    std::memcpy(r.eye, k.eye.data(), sizeof r.eye);
    std::memcpy(r.lookAt, k.lookAt.data(), sizeof r.lookAt);
    std::memcpy(r.up, k.up.data(), sizeof r.up);
    r.fovyDegrees = k.fovyDegrees;
    payload.write(r);
  }
  h.payloadCrc = tsah::crc32(payload.buffer().data(), payload.buffer().size());
  h.headerCrc = tsah::crc32(&h, offsetof(Header, headerCrc));

  tsah::ByteWriter out;
  out.write(h);
  out.append(payload.buffer().data(), payload.buffer().size());
  return std::move(out.buffer());
}

Animation decodeTanim(std::span<const uint8_t> bytes, const std::string& file) {
  tsah::ByteReader in(bytes, file);
  const Header h = in.read<Header>("header");
  if (h.magic != kMagic) throw tsah::FileError(file, "not a .tanim file (bad magic)");
  if (tsah::crc32(&h, offsetof(Header, headerCrc)) != h.headerCrc)
    throw tsah::FileError(file, "header checksum mismatch (corrupt file)");
  if (h.version != 1 && h.version != kVersion)
    throw tsah::FileError(file, "unsupported .tanim version " + std::to_string(h.version) +
                                " (this build reads versions 1 and " + std::to_string(kVersion) + ")");
  if (h.version >= 2 && h.movingVertexCount > h.vertexCount)
    throw tsah::FileError(file, "moving vertex count " + std::to_string(h.movingVertexCount) + " exceeds the vertex count " +
                                std::to_string(h.vertexCount));
  if (h.keyframeCount == 0) throw tsah::FileError(file, "no keyframes");
  if (h.nameBytes > kMaxName) throw tsah::FileError(file, "name length " + std::to_string(h.nameBytes) + " is absurd");
  if (h.cameraKeyCount > kMaxCameraKeys)
    throw tsah::FileError(file, "camera key count " + std::to_string(h.cameraKeyCount) + " is absurd");
  const uint64_t expected = payloadSize(h);
  if (expected == 0 || expected != h.payloadBytes)
    throw tsah::FileError(file, "header counts (" + std::to_string(h.vertexCount) + " vertices, " +
                                std::to_string(h.triangleCount) + " triangles, " +
                                std::to_string(h.keyframeCount) + " keyframes) do not match the payload size");
  if (h.payloadBytes != in.remaining())
    throw tsah::FileError(file, "file holds " + std::to_string(in.remaining()) + " payload bytes, header says " +
                                std::to_string(h.payloadBytes) + (h.payloadBytes > in.remaining() ? " (truncated)" : ""));
  const auto payload = bytes.subspan(in.offset());
  if (tsah::crc32(payload.data(), payload.size()) != h.payloadCrc)
    throw tsah::FileError(file, "payload checksum mismatch (corrupt file)");

  const auto nameBytes = in.bytes(padTo8(h.nameBytes), "name");
  std::string name(reinterpret_cast<const char*>(nameBytes.data()), h.nameBytes);
  // Names end up in messages and reports, which are one line each.
  if (const auto bad = std::find_if(name.begin(), name.end(), isControl); bad != name.end())
    throw tsah::FileError(file, "the animation name holds a control character (byte " +
                                std::to_string(static_cast<unsigned char>(*bad)) + " at " +
                                std::to_string(bad - name.begin()) + ")");
  std::vector<double> times;
  std::vector<uint32_t> indices;
  std::vector<float> rest, positions;
  std::vector<uint32_t> moving;
  in.readArray(times, h.keyframeCount, "keyframe times");
  in.readArray(indices, std::size_t(h.triangleCount) * 3, "triangle indices");
  if (hasStaticPart(h)) {
    in.readArray(rest, std::size_t(h.vertexCount) * 3, "rest positions");
    in.readArray(moving, h.movingVertexCount, "moving vertex ids");
    in.bytes(padTo8(moving.size() * 4) - moving.size() * 4, "padding");
  }
  in.readArray(positions, std::size_t(h.keyframeCount) * keyedVertices(h) * 3, "positions");
  std::vector<CameraKey> camera(h.cameraKeyCount);
  for (auto& k : camera) {
    const auto r = in.read<CameraRecord>("camera key");
    k.time = r.time;
    std::memcpy(k.eye.data(), r.eye, sizeof r.eye);
    std::memcpy(k.lookAt.data(), r.lookAt, sizeof r.lookAt);
    std::memcpy(k.up.data(), r.up, sizeof r.up);
    k.fovyDegrees = r.fovyDegrees;
  }
  checkCameraKeys(camera, file);
  // The consistency checks (index range, times, NaN) name the file, never the stored name: that is
  // free text, and a name holding a line break would break the one-line error.
  Animation a = hasStaticPart(h) ? Animation::withStaticVertices(std::move(indices), std::move(rest), std::move(moving),
                                                                 std::move(positions), std::move(times), file)
                                 : Animation(std::move(indices), h.vertexCount, std::move(positions), std::move(times), file);
  a.setName(std::move(name));
  a.setCameraPath(std::move(camera));
  return a;
}

void saveTanim(const Animation& animation, const std::string& path) {
  tsah::requireExtension(path, ".tanim", "animation");
  tsah::writeFileAtomically(path, encodeTanim(animation));
}

Animation loadTanim(const std::string& path) { return decodeTanim(tsah::readFile(path), path); }

}  // namespace anim
