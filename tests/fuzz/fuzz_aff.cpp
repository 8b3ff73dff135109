// libFuzzer entry point for the BART AFF importer. Each input is parsed as the file fuzz.aff in a
// scratch folder that also holds a few files to include (a triangle, a file including it twice, and
// one including fuzz.aff back, for cycles), then sampled into keyframes. Every input must either be
// rejected with anim::Error (one line, no newline) or give an animation with triangles and keyframes;
// a crash, another exception, a sanitizer report, a hang or a huge allocation is a finding.
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <unistd.h>

#include "anim/bart.hpp"
#include "anim/error.hpp"

namespace {

std::string& scenePath() {
  static std::string path;
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("fuzz-aff-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "tri.aff") << "p 3\n1 0 0\n0 1 0\n0 0 1\n";
  std::ofstream(dir / "two.aff") << "i 0 tri.aff\nxs 1 1 1 0 0 1 90 1 0 0 { i 0 tri.aff }\n";
  std::ofstream(dir / "back.aff") << "i 0 fuzz.aff\n";
  std::ofstream(dir / "fuzz.aff") << "i 0 two.aff\n";
  scenePath() = (dir / "fuzz.aff").string();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  anim::BartOptions options;
  options.maxPositionBytes = 8u << 20;  // keep every accepted input small
  options.maxIncludeDepth = 8;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const anim::Animation a = anim::importBartText(text, scenePath(), options);
    if (a.triangleCount() == 0 || a.keyframeCount() == 0) std::abort();
  } catch (const anim::Error& e) {
    if (std::string_view(e.what()).find('\n') != std::string_view::npos) std::abort();  // not one line
  }
  return 0;
}
