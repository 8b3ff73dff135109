// Replays the committed fuzz corpora (tests/fuzz/corpus/<entry>/) through the same entry points as
// the libFuzzer targets (tests/fuzz/entries.hpp), with every truncation of every file, so a
// regression on any of them, or on an input a fuzzer once found, fails CI without clang. An entry
// returns normally when the parser accepts the input or refuses it with a one-line tsah::Error.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include "entries.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

struct Entry {
  const char* name;
  void (*run)(std::span<const uint8_t>);
};

// Every fuzz target (tests/fuzz/CMakeLists.txt, TSAH_FUZZ_ENTRIES).
constexpr Entry kEntries[] = {
    {"tanim", tsah::fuzz::tanim}, {"obj", tsah::fuzz::obj},         {"mesh", tsah::fuzz::mesh},
    {"md2", tsah::fuzz::md2},     {"manifest", tsah::fuzz::manifest}, {"camera", tsah::fuzz::camera},
    {"pc2", tsah::fuzz::pc2},     {"mdd", tsah::fuzz::mdd},           {"tbvh", tsah::fuzz::tbvh},
    {"treeset", tsah::fuzz::treeset}, {"aff", tsah::fuzz::aff},       {"scene", tsah::fuzz::scene},
    {"writers", tsah::fuzz::writers}, {"twolevel", tsah::fuzz::twolevel},
};

const fs::path& corpusRoot() {
  static const fs::path root = fs::path(TSAH_SOURCE_DIR) / "tests/fuzz/corpus";
  return root;
}

class FuzzCorpora : public testing::TestWithParam<Entry> {};

TEST_P(FuzzCorpora, EveryFileAndPrefixIsAcceptedOrRefusedInOneLine) {
  const Entry entry = GetParam();
  const fs::path dir = corpusRoot() / entry.name;
  std::size_t files = 0;
  for (const auto& f : fs::directory_iterator(dir)) {
    std::ifstream in(f.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    SCOPED_TRACE(f.path().string());
    EXPECT_NO_THROW(entry.run(bytes));
    // Every prefix too: truncation is the commonest corruption.
    for (std::size_t n = 0; n < bytes.size(); n += 1 + bytes.size() / 64)
      EXPECT_NO_THROW(entry.run(std::span(bytes).first(n))) << "prefix of " << n << " bytes";
    ++files;
  }
  EXPECT_GT(files, 0u) << "empty corpus " << dir;
}

INSTANTIATE_TEST_SUITE_P(Entries, FuzzCorpora, testing::ValuesIn(kEntries),
                         [](const testing::TestParamInfo<Entry>& p) { return std::string(p.param.name); });

TEST(FuzzCorporaSet, EveryCorpusFolderHasAnEntry) {
  std::set<std::string> entries;
  for (const Entry& e : kEntries) entries.insert(e.name);
  for (const auto& d : fs::directory_iterator(corpusRoot()))
    EXPECT_TRUE(entries.count(d.path().filename().string())) << d.path() << " is replayed by no entry";
}

TEST(FuzzCorporaSet, EntriesRefuseMultiLineMessages) {
  EXPECT_THROW(tsah::fuzz::requireOneLine("a\nb"), std::logic_error);
  EXPECT_NO_THROW(tsah::fuzz::requireOneLine("x.obj: line 2: bad"));
}

}  // namespace
