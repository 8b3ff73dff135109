#pragma once
// One entry per parser a user can hand the tool. Each parses the bytes as that format and returns
// normally when the input is accepted or refused with anim::Error (a one-line message); anything
// else (a crash, a sanitizer report, another exception type, a multi-line message, an accepted
// result that breaks an invariant) is a finding. The libFuzzer targets (fuzz_main.cpp) call them,
// and tests/test_fuzz_corpora.cpp replays the committed corpora through them without clang.
#include <cstdint>
#include <span>
#include <string>

namespace tsah::fuzz {

void tanim(std::span<const uint8_t> data);     // .tanim (bit 0 of byte 0: repair both CRCs)
void obj(std::span<const uint8_t> data);       // OBJ text (the project's own reader)
void openMesh(std::span<const uint8_t> data);  // byte 0 picks .ply/.off/.stl/.om; through readMesh
void md2(std::span<const uint8_t> data);       // MD2 models
void manifest(std::span<const uint8_t> data);  // JSON frame manifests
void camera(std::span<const uint8_t> data);    // camera files of `tsah trace --camera`

// Throws std::logic_error when an anim::Error message is not one line (the CLI prints one line).
void requireOneLine(const char* what);

}  // namespace tsah::fuzz
