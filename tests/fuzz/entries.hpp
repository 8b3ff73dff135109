#pragma once
// One entry per parser a user can hand the tool. Each parses the bytes as that format and returns
// normally when the input is accepted or refused with tsah::Error (a one-line message); anything
// else (a crash, a sanitizer report, another exception type, a multi-line message, an accepted
// result that breaks an invariant) is a finding. The libFuzzer targets (fuzz_main.cpp, one per
// entry, named fuzz_<entry>) call them, and tests/test_fuzz_corpora.cpp replays the committed
// corpora (corpus/<entry>/) through them without clang. docs/fuzzing.md lists what each covers.
#include <cstdint>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "tsah/base/error.hpp"

namespace tsah::fuzz {

// entries_formats.cpp: single-file formats decoded from bytes.
void tanim(std::span<const uint8_t> data);     // .tanim (bit 0 of byte 0: repair both CRCs)
void obj(std::span<const uint8_t> data);       // OBJ text (the project's own reader)
void mesh(std::span<const uint8_t> data);      // byte 0 picks .ply/.off/.stl/.om; through readMesh
void md2(std::span<const uint8_t> data);       // MD2 models
void manifest(std::span<const uint8_t> data);  // JSON frame manifests
void camera(std::span<const uint8_t> data);    // camera files of `tsah trace --camera`
void pc2(std::span<const uint8_t> data);       // PC2 point caches (point_cache_check.hpp)
void mdd(std::span<const uint8_t> data);       // MDD point caches

// entries_trees.cpp: tree files.
void tbvh(std::span<const uint8_t> data);      // version 1 .tbvh (bit 0 of byte 0: repair the CRC)
void treeset(std::span<const uint8_t> data);   // .tbvh read as a tree set, version 1 or 2 (byte 0: CRC repairs)
void twolevel(std::span<const uint8_t> data);  // .tbvh version 3, two-level scenes (byte 0: CRC repairs)

// entries_scenes.cpp: inputs that name other files, read in a scratch folder of small objects.
void aff(std::span<const uint8_t> data);       // BART .aff with includes
void scene(std::span<const uint8_t> data);     // a .json through anim::load: scene, point-cache or frame manifest

// entries_writers.cpp: an animation made from the bytes through a writer and its own reader.
void writers(std::span<const uint8_t> data);   // .tanim, PC2, MDD or a tree set (byte 0), see the file

// Throws std::logic_error when an tsah::Error message is not one line (the CLI prints one line).
void requireOneLine(const char* what);

// Runs `parse`; tsah::Error is a clean refusal (checked to be one line), other exceptions escape.
template <typename F>
void refuseCleanly(F&& parse) {
  try {
    parse();
  } catch (const tsah::Error& e) {
    requireOneLine(e.what());
  }
}

// A per-process scratch folder (in /dev/shm when there is one: no disk traffic), created once.
const std::filesystem::path& scratchFolder();
void writeBytes(const std::filesystem::path& path, std::span<const uint8_t> data);
void writeText(const std::filesystem::path& path, std::string_view text);

}  // namespace tsah::fuzz
