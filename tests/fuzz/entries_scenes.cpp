// Fuzz entries for inputs that name other files: BART .aff scenes (with includes) and .json inputs
// read through anim::load (scene files, point-cache manifests, frame manifests). Each input is the
// file fuzz.aff / fuzz.json in a per-process scratch folder that also holds small objects to name.
// The harness keeps the file system to that folder: inputs holding '/' or '\' or ".." are skipped.
#include <cstdlib>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "anim/bart.hpp"
#include "anim/load.hpp"
#include "anim/point_cache.hpp"
#include "anim/tanim.hpp"
#include "entries.hpp"

namespace tsah::fuzz {

namespace {

namespace fs = std::filesystem;

// Inputs of an accepted scene stay small: the memory statement refuses beyond this.
constexpr const char* kMemoryLimitMiB = "256";

bool leavesScratchFolder(std::span<const uint8_t> data) {
  const std::string_view text(reinterpret_cast<const char*>(data.data()), data.size());
  return text.find_first_of("/\\") != std::string_view::npos || text.find("..") != std::string_view::npos;
}

constexpr const char* kTriangleAff = "p 3\n1 0 0\n0 1 0\n0 0 1\n";

// The folder `name` in the scratch folder, holding the given files (name, text).
fs::path folderWith(const char* name, std::initializer_list<std::pair<const char*, std::string_view>> files) {
  const fs::path d = scratchFolder() / name;
  fs::create_directories(d);
  for (const auto& [file, text] : files) writeText(d / file, text);
  return d;
}

// The objects a fuzzed scene or manifest can name (written once per process).
const fs::path& objectFolder() {
  static const fs::path dir = [] {
    ::setenv("TSAH_MEMORY_LIMIT_MB", kMemoryLimitMiB, 0);
    const fs::path d = folderWith(
        "objects",
        {{"tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         {"quad.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"},
         {"f_0.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         {"f_1.obj", "v 0 0 1\nv 1 0 1\nv 0 1 1\nf 1 2 3\n"},
         {"tri.aff", kTriangleAff},
         {"moving.json",
          R"({"objects": [{"file": "tri.obj", "path": [{"time": 0}, {"time": 2, "translate": [1, 0, 0]}]}]})"},
         {"cached.json", R"({"mesh": "tri.obj", "cache": "tri.pc2"})"},
         {"frames.json", R"(["f_0.obj", "f_1.obj"])"},
         {"back.json", R"({"objects": [{"file": "fuzz.json"}]})"}});  // a cycle through the input
    // Two keyframes of the triangle, as a .tanim and as point caches of tri.obj's points.
    const anim::Animation wave({0, 1, 2}, 3, {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1}, {0.0, 1.0}, "wave");
    writeBytes(d / "wave.tanim", anim::encodeTanim(wave));
    writeBytes(d / "tri.pc2", anim::encodePc2(wave));
    writeBytes(d / "tri.mdd", anim::encodeMdd(wave));
    return d;
  }();
  return dir;
}

// The AFF include targets: a triangle, a file including it twice, one including fuzz.aff back.
const fs::path& affFolder() {
  static const fs::path dir = folderWith("aff", {{"tri.aff", kTriangleAff},
                                                 {"two.aff", "i 0 tri.aff\nxs 1 1 1 0 0 1 90 1 0 0 { i 0 tri.aff }\n"},
                                                 {"back.aff", "i 0 fuzz.aff\n"},
                                                 {"fuzz.aff", "i 0 two.aff\n"}});
  return dir;
}

void requireUsable(const anim::Animation& a, const char* what) {
  if (a.triangleCount() == 0 || a.keyframeCount() == 0) throw std::logic_error(std::string(what) + ": accepted without triangles or keyframes");
}

}  // namespace

void aff(std::span<const uint8_t> data) {
  anim::BartOptions options;
  options.maxPositionBytes = 8u << 20;  // keep every accepted input small
  options.maxIncludeDepth = 8;
  const std::string_view text(reinterpret_cast<const char*>(data.data()), data.size());
  refuseCleanly([&] { requireUsable(anim::importBartText(text, (affFolder() / "fuzz.aff").string(), options), "aff"); });
}

void scene(std::span<const uint8_t> data) {
  if (leavesScratchFolder(data)) return;
  const fs::path input = objectFolder() / "fuzz.json";
  writeBytes(input, data);
  anim::LoadOptions options;
  options.resolveDataPath = [](const std::string& rel) { return (objectFolder() / rel).string(); };
  refuseCleanly([&] { requireUsable(anim::load(input.string(), options), "scene"); });
}

}  // namespace tsah::fuzz
