// Traversal storage in huge pages (tsah/base/huge_pages.hpp): large arrays 2 MiB-aligned, whole
// 2 MiB pages, advised to transparent huge pages before their first touch; small ones ordinary
// aligned allocations; a wide tree's packets held that way.
#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include "anim/generators.hpp"
#include "tsah/base/huge_pages.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/wide_layout.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "test_support.hpp"

namespace {

using tsah::kHugePageBytes;
using tsah::TraversalVector;

bool alignedTo(const void* p, std::size_t alignment) { return reinterpret_cast<std::uintptr_t>(p) % alignment == 0; }

// The VmFlags of the mapping of /proc/self/smaps that holds `p` ("" when it cannot be read). A
// mapping's first line is "first-last perms ..." in hex; its field lines start with a name.
std::string vmFlagsOf(const void* p) {
  std::ifstream smaps("/proc/self/smaps");
  const auto at = reinterpret_cast<std::uintptr_t>(p);
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    std::uintptr_t first = 0, last = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> first >> dash >> last && dash == '-')
      inside = first <= at && at < last;
    else if (inside && line.rfind("VmFlags:", 0) == 0)
      return line;
  }
  return "";
}

// Whether the memory at `p` was advised to huge pages ("hg", MADV_HUGEPAGE, among the VmFlags of
// its mapping); none where /proc/self/smaps cannot be read (not Linux).
std::optional<bool> advisedToHugePages(const void* p) {
  const std::string flags = vmFlagsOf(p);
  if (flags.empty()) return std::nullopt;
  return flags.find(" hg") != std::string::npos;
}

TEST(HugePages, SmallArraysAreOrdinaryAlignedAllocations) {
  TraversalVector<tsah::WideSoaNode<8>> nodes(10);
  EXPECT_TRUE(alignedTo(nodes.data(), alignof(tsah::WideSoaNode<8>)));
  for (std::size_t i = 0; i < nodes.size(); ++i) nodes[i].ref[0] = int32_t(i);
  for (std::size_t i = 0; i < nodes.size(); ++i) EXPECT_EQ(nodes[i].ref[0], int32_t(i));
  TraversalVector<uint8_t> bytes(1);
  bytes[0] = 7;
  EXPECT_EQ(bytes[0], 7);
}

TEST(HugePages, LargeArraysStartOnA2MiBBoundaryAndAreAdvised) {
  const std::size_t count = 3 * kHugePageBytes / sizeof(tsah::WoopPacket<8>) + 5;  // past 3 pages: 4 whole ones
  TraversalVector<tsah::WoopPacket<8>> packets(count);
  EXPECT_TRUE(alignedTo(packets.data(), kHugePageBytes));
  for (std::size_t i = 0; i < count; ++i) packets[i].slot[7] = uint32_t(i);  // the last bytes of every packet
  for (std::size_t i = 0; i < count; ++i) ASSERT_EQ(packets[i].slot[7], uint32_t(i));
  const std::optional<bool> advised = advisedToHugePages(packets.data());
  if (!advised) GTEST_SKIP() << "/proc/self/smaps cannot be read here";
  EXPECT_TRUE(*advised) << "no MADV_HUGEPAGE on the array's mapping: " << vmFlagsOf(packets.data());
}

TEST(HugePages, GrowingAcrossTheThresholdKeepsTheContents) {
  TraversalVector<uint32_t> v;
  const std::size_t count = 2 * kHugePageBytes / sizeof(uint32_t) + 3;
  for (std::size_t i = 0; i < count; ++i) v.push_back(uint32_t(i * 2654435761u));
  EXPECT_TRUE(alignedTo(v.data(), kHugePageBytes));
  for (std::size_t i = 0; i < count; ++i) ASSERT_EQ(v[i], uint32_t(i * 2654435761u));
  v.resize(10);
  v.shrink_to_fit();  // back below the threshold: an ordinary allocation again
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(v[i], uint32_t(i * 2654435761u));
}

TEST(HugePages, AWideTreesPacketsAreInHugePageStorage) {
  // About 7,500 eight-lane Woop packets of 416 bytes: 3 MiB (0.3 MB of nodes, under the threshold).
  const auto a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 40000, 1);
  const auto positions = a.positionsAt(a.startTime());
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), positions, 1);
  tsah::Bvh bvh = tsah::BinnedSahBuilder().build(boxes.frame(0));
  tsah::CpuRuntime::Config c;
  c.threads = 2;
  c.layout = tsah::Layout::Bvh8;
  tsah::CpuRuntime rt(tsah::flattenBvh(bvh), {a.indices().begin(), a.indices().end()}, a.vertexCount(), c);
  const tsah::WideTree<8>* tree = rt.wide8();
  ASSERT_NE(tree, nullptr);
  ASSERT_GE(tree->packets().size_bytes(), kHugePageBytes);
  EXPECT_TRUE(alignedTo(tree->packets().data(), kHugePageBytes));
  const std::optional<bool> advised = advisedToHugePages(tree->packets().data());
  if (!advised) GTEST_SKIP() << "/proc/self/smaps cannot be read here";
  EXPECT_TRUE(*advised) << "no MADV_HUGEPAGE on the array's mapping: " << vmFlagsOf(tree->packets().data());
}

}  // namespace
