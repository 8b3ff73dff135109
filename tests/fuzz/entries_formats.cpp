#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "anim/assimp_import.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "anim/mesh_sequence.hpp"
#include "anim/tanim.hpp"
#include "camera_file.hpp"
#include "entries.hpp"
#include "point_cache_check.hpp"

namespace tsah::fuzz {

void requireOneLine(const char* what) {
  if (std::string_view(what).find('\n') != std::string_view::npos)
    throw std::logic_error(std::string("error message is not one line: ") + what);
}

const std::filesystem::path& scratchFolder() {
  // Never destroyed, so that the exit handler below can still name it.
  static const std::filesystem::path* const dir = [] {
    std::error_code ec;
    const std::filesystem::path shm("/dev/shm");
    const auto base = std::filesystem::is_directory(shm, ec) ? shm : std::filesystem::temp_directory_path();
    auto* d = new std::filesystem::path(base / ("tsah-fuzz-" + std::to_string(::getpid())));
    std::filesystem::create_directories(*d);
    std::atexit([] {  // nothing is left behind by test runs and fuzzer runs that end normally
      std::error_code ignored;
      std::filesystem::remove_all(scratchFolder(), ignored);
    });
    return d;
  }();
  return *dir;
}

void writeBytes(const std::filesystem::path& path, std::span<const uint8_t> data) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot write " + path.string());
  const bool ok = std::fwrite(data.data(), 1, data.size(), f) == data.size();
  if (std::fclose(f) != 0 || !ok) throw std::runtime_error("cannot write " + path.string());
}

void writeText(const std::filesystem::path& path, std::string_view text) {
  writeBytes(path, {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
}

namespace {

void requireValidMesh(const anim::MeshFrame& m) {
  if (m.indices.size() % 3 != 0) throw std::logic_error("mesh: index count not a multiple of 3");
  for (uint32_t i : m.indices)
    if (std::size_t(i) * 3 >= m.positions.size()) throw std::logic_error("mesh: accepted an index past the vertices");
}

}  // namespace

void tanim(std::span<const uint8_t> data) {
  if (data.empty()) return;
  std::vector<uint8_t> bytes(data.begin() + 1, data.end());
  if ((data[0] & 1) && bytes.size() >= 64) {  // repair the checksums so the fuzzer gets past them
    const uint64_t payloadBytes = bytes.size() - 64;
    std::memcpy(bytes.data() + 40, &payloadBytes, 8);
    const uint32_t payloadCrc = tsah::crc32(bytes.data() + 64, bytes.size() - 64);
    std::memcpy(bytes.data() + 48, &payloadCrc, 4);
    const uint32_t headerCrc = tsah::crc32(bytes.data(), 60);
    std::memcpy(bytes.data() + 60, &headerCrc, 4);
  }
  refuseCleanly([&] {
    const anim::Animation a = anim::decodeTanim(bytes, "fuzz.tanim");
    // An accepted file round-trips: its re-encoding (the current version, which may store static
    // vertices once where the input was version 1) reads back as the same animation and is canonical.
    const std::vector<uint8_t> again = anim::encodeTanim(a);
    const anim::Animation b = anim::decodeTanim(again, "fuzz.tanim");
    if (anim::encodeTanim(b) != again || b.allPositions() != a.allPositions() ||
        !std::equal(a.indices().begin(), a.indices().end(), b.indices().begin(), b.indices().end()) ||
        !std::equal(a.times().begin(), a.times().end(), b.times().begin(), b.times().end()))
      throw std::logic_error("tanim: accepted file does not round-trip");
  });
}

void obj(std::span<const uint8_t> data) {
  refuseCleanly([&] { requireValidMesh(anim::decodeObj(data, "fuzz.obj")); });
}

void mesh(std::span<const uint8_t> data) {
  if (data.empty()) return;
  static const char* const kExtensions[] = {".ply", ".off", ".stl", ".om"};
  // OpenMesh reads from a path, so the input goes through a scratch file and the project's
  // wrapper, readMesh.
  const std::filesystem::path path = scratchFolder() / (std::string("mesh") + kExtensions[data[0] % 4]);
  writeBytes(path, data.subspan(1));
  refuseCleanly([&] { requireValidMesh(anim::readMesh(path.string())); });
  std::filesystem::remove(path);
}

void md2(std::span<const uint8_t> data) {
  refuseCleanly([&] {
    (void)anim::md2Clips(data, "fuzz.md2");
    const anim::Animation a = anim::decodeMd2(data, "fuzz.md2");
    if (a.keyframeCount() == 0) throw std::logic_error("md2: accepted without keyframes");
  });
}

void manifest(std::span<const uint8_t> data) {
  refuseCleanly([&] {
    const anim::FrameList list = anim::decodeManifest(data, "/fuzz/manifest.json");
    if (list.files.empty()) throw std::logic_error("manifest: accepted without frames");
    if (!list.times.empty() && list.times.size() != list.files.size())
      throw std::logic_error("manifest: times do not match frames");
  });
}

void camera(std::span<const uint8_t> data) {
  refuseCleanly([&] {
    if (tsah::cli::decodeCameraFile(data, "fuzz.json").empty()) throw std::logic_error("camera: no keys");
  });
}

namespace {

void pointCache(std::span<const uint8_t> data, anim::PointCacheFormat format) {
  if (const auto finding = anim::fuzz::pointCacheFinding(data, format)) throw std::logic_error(*finding);
}

}  // namespace

void pc2(std::span<const uint8_t> data) { pointCache(data, anim::PointCacheFormat::Pc2); }
void mdd(std::span<const uint8_t> data) { pointCache(data, anim::PointCacheFormat::Mdd); }

}  // namespace tsah::fuzz
