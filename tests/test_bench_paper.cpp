// The paper's figures the bench prints beside its own (bench/paper.hpp): lookup rules, and the
// transcription checked against the paper's text where that is available.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "bench/paper.hpp"
#include "test_support.hpp"

namespace {

using tsah::bench::findPaperScene;
using tsah::bench::paperScenes;

TEST(BenchPaper, EveryTableHasTheBenchMethodsInThePapersOrder) {
  const std::vector<std::string> t1 = {"rebuild", "sahstar", "sah0", "tsah0", "tsah2", "tsah4"};
  const std::vector<std::string> t2 = {"rebuild", "sahstar", "sah0", "tsah0", "lbvh", "hlbvh-sah"};
  ASSERT_EQ(paperScenes().size(), 3u);
  for (const auto& s : paperScenes()) {
    ASSERT_EQ(s.table1.size(), t1.size()) << s.paperName;
    ASSERT_EQ(s.table2.size(), t2.size()) << s.paperName;
    for (std::size_t i = 0; i < t1.size(); ++i) EXPECT_EQ(s.table1[i].method, t1[i]) << s.paperName;
    for (std::size_t i = 0; i < t2.size(); ++i) EXPECT_EQ(s.table2[i].method, t2[i]) << s.paperName;
    for (const auto& r : s.table1) EXPECT_LE(r.average, r.maximum) << s.paperName << " " << r.method;
    EXPECT_EQ(s.table2[0].updateMs, 0.0) << "SAH-rebuild trees are precomputed";
  }
}

TEST(BenchPaper, ScenesMatchByNameAndTriangleCount) {
  const auto* robots = findPaperScene("robot", 71708);
  ASSERT_NE(robots, nullptr);
  EXPECT_EQ(robots->paperName, "BART Robots");
  EXPECT_EQ(findPaperScene("Robots", 71708), robots);
  EXPECT_EQ(findPaperScene("robot", 60000), nullptr) << "another version of the scene is not compared";
  const auto* kitchen = findPaperScene("kitchen", 110561);
  ASSERT_NE(kitchen, nullptr);
  EXPECT_EQ(kitchen->table1[3].average, 26);
  EXPECT_EQ(findPaperScene("horse-gallop", 16843), nullptr);
  // BART Museum: the paper's version has 75.8k triangles, the data's level 5 has 11,564: context only.
  EXPECT_EQ(findPaperScene("museum", 11564), nullptr);
  const auto* museum = findPaperScene("museum", 11564, false);
  ASSERT_NE(museum, nullptr);
  EXPECT_FALSE(museum->sameScene);
  EXPECT_EQ(museum->table2Segmented.size(), 6u);
}

TEST(BenchPaper, JsonCarriesEveryFigure) {
  const nlohmann::json j = tsah::bench::paperJson(*findPaperScene("museum", 0, false));
  EXPECT_EQ(j["paper_name"], "BART Museum");
  EXPECT_FALSE(j["same_scene"].get<bool>());
  EXPECT_EQ(j["table1"].size(), 6u);
  EXPECT_EQ(j["table2"][5]["method"], "hlbvh-sah");
  EXPECT_DOUBLE_EQ(j["table2_segmented"][3]["total_ms"].get<double>(), 110.8);
  EXPECT_NE(j["source"].get<std::string>().find("Eurographics 2015"), std::string::npos);
}

// The paper as text (../shared/paper next to the checkout), or empty.
std::string paperText() {
  const std::filesystem::path p =
      std::filesystem::path(TSAH_SOURCE_DIR) / ".." / "shared" / "paper" / "tsah-bittner-meister-2015.txt";
  std::ifstream in(p);
  if (!in) return {};
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<double> numbersAfter(const std::string& text, std::size_t at, std::size_t count) {
  std::istringstream in(text.substr(at));
  std::vector<double> out;
  std::string word;
  while (out.size() < count && in >> word) {
    char* end = nullptr;
    const double v = std::strtod(word.c_str(), &end);
    if (end == word.c_str() + word.size()) out.push_back(v);
  }
  return out;
}

TEST(BenchPaper, Table2AsInThePapersText) {
  const std::string text = paperText();
  if (text.empty()) GTEST_SKIP() << "the paper's text is not next to the checkout";
  // Table 2, first block: rows of 5 scenes x (update, MRays/s, total): Robots, Museum, Museum*, Cloth Ball, Kitchen.
  const std::size_t block = text.find("BART Robots BART Museum BART Museum* Cloth Ball BART Kitchen SAH-rebuild");
  ASSERT_NE(block, std::string::npos);
  const std::vector<std::string> labels = {"SAH-rebuild", "SAH\u2217", "SAH0", "T-SAH Cf0", "HLBVH-med", "HLBVH-SAH"};
  const auto* robots = findPaperScene("robot", 71500);
  const auto* kitchen = findPaperScene("kitchen", 110500);
  const auto* museum = findPaperScene("museum", 0, false);
  std::size_t at = block;
  for (std::size_t row = 0; row < labels.size(); ++row) {
    at = text.find(labels[row] + " ", at);
    ASSERT_NE(at, std::string::npos) << labels[row];
    const std::vector<double> v = numbersAfter(text, at + labels[row].size(), 15);
    ASSERT_EQ(v.size(), 15u);
    auto expectRow = [&](const tsah::bench::PaperRuntimeRow& r, std::size_t first, const char* scene) {
      EXPECT_DOUBLE_EQ(r.updateMs, v[first]) << scene << " " << labels[row];
      EXPECT_DOUBLE_EQ(r.mraysPerSecond, v[first + 1]) << scene << " " << labels[row];
      EXPECT_DOUBLE_EQ(r.totalMs, v[first + 2]) << scene << " " << labels[row];
    };
    expectRow(robots->table2[row], 0, "Robots");
    expectRow(museum->table2[row], 3, "Museum");
    expectRow(museum->table2Segmented[row], 6, "Museum*");
    expectRow(kitchen->table2[row], 12, "Kitchen");
    at += labels[row].size();
  }
}

TEST(BenchPaper, Table1RowsAsInThePapersText) {
  const std::string text = paperText();
  if (text.empty()) GTEST_SKIP() << "the paper's text is not next to the checkout";
  const std::vector<std::string> labels = {"SAH-rebuild", "SAH\u2217", "SAH0", "T-SAH Cf0", "T-SAH Cf2", "T-SAH Cf4"};
  // Table 1 lists each scene's rows as "label build cost max"; the scene's column block starts at
  // its name. Robots and Museum share a block (Robots first), Kitchen starts another.
  struct Case {
    const tsah::bench::PaperScene* scene;
    const char* block;
    int column;  // 0: first scene of the block, 1: second
  };
  const std::vector<Case> cases = {{findPaperScene("robot", 71500), "BART Robots BART Museum Cloth Ball # triangles", 0},
                                   {findPaperScene("museum", 0, false), "BART Robots BART Museum Cloth Ball # triangles", 1},
                                   {findPaperScene("kitchen", 110500), "BART Kitchen 24 Cell Fairy Forest # triangles", 0}};
  for (const Case& c : cases) {
    std::size_t at = text.find(c.block);
    ASSERT_NE(at, std::string::npos) << c.block;
    for (std::size_t row = 0; row < labels.size(); ++row) {
      for (int skip = 0; skip <= c.column; ++skip) {
        at = text.find(labels[row] + " ", at);
        ASSERT_NE(at, std::string::npos);
        if (skip < c.column) at += labels[row].size();
      }
      const std::vector<double> v = numbersAfter(text, at + labels[row].size(), 3);
      ASSERT_EQ(v.size(), 3u);
      EXPECT_DOUBLE_EQ(c.scene->table1[row].buildSeconds, v[0]) << c.scene->paperName << " " << labels[row];
      EXPECT_DOUBLE_EQ(c.scene->table1[row].average, v[1]) << c.scene->paperName << " " << labels[row];
      EXPECT_DOUBLE_EQ(c.scene->table1[row].maximum, v[2]) << c.scene->paperName << " " << labels[row];
      at += labels[row].size();
    }
  }
}

}  // namespace
