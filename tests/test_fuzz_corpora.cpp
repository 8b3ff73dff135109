// Replays the committed fuzz corpora (tests/fuzz_inputs/corpus/<parser>/) through the same entry
// points as the libFuzzer targets, so a regression on any of them fails CI without clang. An entry
// returns normally when the parser accepts the input or refuses it with a one-line anim::Error.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <vector>

#include "fuzz_entries.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

void replay(const std::string& parser, const std::function<void(std::span<const uint8_t>)>& entry) {
  const fs::path dir = fs::path(TSAH_SOURCE_DIR) / "tests/fuzz_inputs/corpus" / parser;
  std::size_t files = 0;
  for (const auto& f : fs::directory_iterator(dir)) {
    std::ifstream in(f.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    SCOPED_TRACE(f.path().string());
    EXPECT_NO_THROW(entry(bytes));
    // Every prefix too: truncation is the commonest corruption.
    for (std::size_t n = 0; n < bytes.size(); n += 1 + bytes.size() / 64)
      EXPECT_NO_THROW(entry(std::span(bytes).first(n))) << "prefix of " << n << " bytes";
    ++files;
  }
  EXPECT_GT(files, 0u) << "empty corpus " << dir;
}

}  // namespace

TEST(FuzzCorpora, Tanim) { replay("tanim", tsah::fuzz::tanim); }
TEST(FuzzCorpora, Obj) { replay("obj", tsah::fuzz::obj); }
TEST(FuzzCorpora, OpenMeshFormats) { replay("mesh", tsah::fuzz::openMesh); }
TEST(FuzzCorpora, Md2) { replay("md2", tsah::fuzz::md2); }
TEST(FuzzCorpora, Manifest) { replay("manifest", tsah::fuzz::manifest); }
TEST(FuzzCorpora, Camera) { replay("camera", tsah::fuzz::camera); }

TEST(FuzzCorpora, EntriesRefuseMultiLineMessages) {
  EXPECT_THROW(tsah::fuzz::requireOneLine("a\nb"), std::logic_error);
  EXPECT_NO_THROW(tsah::fuzz::requireOneLine("x.obj: line 2: bad"));
}
