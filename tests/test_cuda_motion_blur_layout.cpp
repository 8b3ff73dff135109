// The CUDA runtime's blurred layout (docs/motion-blur.md#memory): every node record and every slot
// triangle equals the key arrays it is built from (node n's record of segment s at
// n * (keys - 1) + s, slot s's vertices at key k at s * keys + k), through shutters of the same key
// count (the blurred update's graph replayed) and of another (captured again), from the animation
// and from host positions. And
// the instant state that updateShutterAt leaves (the last key's, taken from the batch) equals an
// update at the shutter's close. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/blurred_node.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;

tsah::FlatBvh sahTree(const anim::Animation& a, uint32_t maxLeaf) {
  tsah::Bvh bvh = tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  tsah::LeafCollapser::Config c;
  c.maxLeafSize = maxLeaf;
  return tsah::flattenBvh(maxLeaf > 1 ? tsah::LeafCollapser(c).collapse(bvh) : bvh);
}

// Node n at key k as the layout's records hold it: its child boxes pre-padded over every key
// (motion::prepadBox of the largest magnitude per axis).
tsah::GpuBvhNode prepaddedNode(const std::vector<tsah::FlatBvh>& keyTrees, uint32_t n, uint32_t k) {
  tsah::GpuBvhNode node = keyTrees[k].nodes[n];
  for (int c = 0; c < 2; ++c) {
    tsah::Vec3 m{0.0f, 0.0f, 0.0f};
    for (const tsah::FlatBvh& tree : keyTrees) m = tsah::motion::foldMagnitudes(tree.nodes[n].childBox(c), m);
    node.setChildBox(c, tsah::motion::prepadBox(node.childBox(c), m));
  }
  return node;
}

// What node n's record of segment s holds: motion::encodeNodeSegment of its pre-padded nodes at
// keys s and s + 1, alike when its child boxes are the same bits at every key.
tsah::motion::BlurredNodeSegment expectedRecord(const std::vector<tsah::FlatBvh>& keyTrees, uint32_t n, uint32_t s) {
  bool alike = true;
  for (const tsah::FlatBvh& tree : keyTrees)
    alike &= std::memcmp(&tree.nodes[n], &keyTrees[0].nodes[n], 12 * sizeof(float)) == 0;
  return tsah::motion::encodeNodeSegment(prepaddedNode(keyTrees, n, s), prepaddedNode(keyTrees, n, s + 1), alike);
}

// The layout against the key arrays of the same frame, record by record, bit for bit.
// alikeNodes (when given) gets how many nodes are alike at every key.
void expectLayoutOfTheKeys(const tc::GpuRuntime& gpu, const anim::Animation& a, const std::string& what,
                           uint32_t* alikeNodes = nullptr) {
  const tc::GpuRuntime::BlurredLayoutCopy layout = gpu.downloadBlurredLayout();
  const uint32_t keys = gpu.shutterKeyCount();
  ASSERT_GE(keys, 2u) << what;
  ASSERT_EQ(layout.keys, keys) << what;
  const auto idx = a.indices();
  std::vector<tsah::FlatBvh> keyTrees;
  std::vector<std::vector<float>> keyPositions;
  for (uint32_t k = 0; k < keys; ++k) {
    keyTrees.push_back(gpu.downloadKeyTree(k));
    keyPositions.push_back(gpu.downloadKeyPositions(k));
  }
  const uint32_t slots = a.triangleCount();
  uint32_t alike = 0;
  const uint32_t interior = keyTrees[0].interiorCount;
  ASSERT_EQ(layout.nodes.size(), std::size_t(keys - 1) * interior) << what;
  for (uint32_t seg = 0; seg + 1 < keys; ++seg)
    for (uint32_t n = 0; n < interior; ++n) {
      const tsah::motion::BlurredNodeSegment expect = expectedRecord(keyTrees, n, seg);
      ASSERT_EQ(0, std::memcmp(&layout.nodes[std::size_t(n) * (keys - 1) + seg], &expect, sizeof expect))
          << "node " << n << ", " << what << ", segment " << seg;
      alike += seg == 0 && (expect.node.count0 & tsah::motion::kKeysAlikeBit) ? 1 : 0;
    }
  for (uint32_t k = 0; k < keys; ++k) {
    const tsah::FlatBvh& tree = keyTrees[k];
    const std::vector<float>& p = keyPositions[k];
    const std::string at = what + ", key " + std::to_string(k);
    ASSERT_EQ(layout.triangles.size(), std::size_t(keys) * slots * 12) << at;
    for (uint32_t s = 0; s < slots; ++s) {
      const float* record = layout.triangles.data() + (std::size_t(s) * keys + k) * 12;
      const uint32_t* tri = idx.data() + 3 * std::size_t(tree.triIndex[s]);
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(0, std::memcmp(record + 3 * c, p.data() + 3 * std::size_t(tri[c]), 3 * sizeof(float)))
            << "slot " << s << ", vertex " << c << ", " << at;
      for (int pad = 9; pad < 12; ++pad) ASSERT_EQ(record[pad], 0.0f) << "slot " << s << ", " << at;
    }
  }
  std::printf("[ layout   ] %s: %u of %u nodes alike at every key\n", what.c_str(), alike, keyTrees[0].interiorCount);
  if (alikeNodes) *alikeNodes = alike;
}

// Shutters of two keys in a row (the graph replayed with each frame's keys), then of five keys
// (captured, the key arrays grown), two keys again (captured again for the grown arrays), five keys
// again (that graph replayed); with and without graphs, leaves of 1 and 8 triangles.
TEST(CudaMotionBlurLayout, RecordsEqualTheKeyArraysTheyAreBuiltFrom) {
  REQUIRE_GPU();
  const auto a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 2500, 6, 3);
  const double t0 = a.startTime(), span = a.endTime() - a.startTime();
  for (uint32_t maxLeaf : {1u, 8u}) {
    const tsah::FlatBvh tree = sahTree(a, maxLeaf);
    for (bool graphs : {true, false}) {
      tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
      for (auto [open, close] : {std::pair{0.02, 0.06}, std::pair{0.04, 0.09}, std::pair{0.25, 0.95},
                                 std::pair{0.41, 0.43}, std::pair{0.3, 0.9}}) {
        const std::string what = "leaf " + std::to_string(maxLeaf) + ", graphs " + std::to_string(graphs) +
                                 ", shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]";
        gpu.updateShutterAt(t0 + open * span, t0 + close * span);
        ASSERT_TRUE(gpu.blurred()) << what;
        expectLayoutOfTheKeys(gpu, a, what);
      }
      // From host positions: the same layout of those keys.
      const std::vector<double> times = tsah::motion::shutterKeys(a.times(), t0 + 0.1 * span, t0 + 0.7 * span);
      std::vector<std::vector<float>> positions;
      for (double t : times) positions.push_back(a.positionsAt(t));
      const std::vector<std::span<const float>> spans(positions.begin(), positions.end());
      gpu.updateShutter(tsah::motion::keyFractions(times), spans);
      expectLayoutOfTheKeys(gpu, a, "host positions, leaf " + std::to_string(maxLeaf));
    }
  }
}

// A still part beside a moving one: its nodes are marked alike at every key (and the moving part's
// are not), through shutters of two and of several keys.
TEST(CudaMotionBlurLayout, StillPartsAreMarkedAlikeAtEveryKey) {
  REQUIRE_GPU();
  const anim::Animation a = tsah::test::mostlyStaticAnimation(3000, 600);
  const double t0 = a.startTime(), span = a.endTime() - a.startTime();
  tc::GpuRuntime gpu(sahTree(a, 4), a);
  for (auto [open, close] : {std::pair{0.1, 0.15}, std::pair{0.1, 0.9}}) {
    gpu.updateShutterAt(t0 + open * span, t0 + close * span);
    uint32_t alike = 0;
    expectLayoutOfTheKeys(gpu, a, "mostly static, shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]",
                          &alike);
    EXPECT_GT(alike, 0u);
    EXPECT_LT(alike, gpu.downloadKeyTree(0).interiorCount);
  }
}

// updateShutterAt refits each key once and takes the instant state from the batch's last key: its
// tree, positions, Woop triangles and hits without times equal a fresh runtime's updateAt(close),
// bit for bit, and so does the next instant update (which refits only the moving parts of a scene
// with static subtrees, on the boxes the blurred update left).
TEST(CudaMotionBlurLayout, TheInstantStateIsTheLastKeysUpdate) {
  REQUIRE_GPU();
  for (const bool mostlyStatic : {false, true}) {
    const anim::Animation a = mostlyStatic ? tsah::test::mostlyStaticAnimation(3000, 600)
                                           : tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 3000, 5, 2);
    const tsah::FlatBvh tree = sahTree(a, 4);
    const double t0 = a.startTime(), span = a.endTime() - a.startTime();
    for (bool graphs : {true, false}) {
      const std::string what = std::string(mostlyStatic ? "mostly static" : "wave") + ", graphs " +
                               std::to_string(graphs);
      tc::GpuRuntime blurred(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
      tc::GpuRuntime instant(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
      blurred.updateAt(t0 + 0.5 * span);  // static boxes in place: the blurred update must keep them right
      const double open = t0 + 0.15 * span, close = t0 + 0.6 * span;
      blurred.updateShutterAt(open, close);
      ASSERT_TRUE(blurred.blurred()) << what;
      instant.updateAt(close);
      const tsah::FlatBvh expect = instant.downloadTree();
      const tsah::FlatBvh got = blurred.downloadTree();
      ASSERT_EQ(got.interiorCount, expect.interiorCount) << what;
      ASSERT_EQ(0, std::memcmp(got.nodes.data(), expect.nodes.data(), expect.nodes.size() * sizeof(tsah::GpuBvhNode)))
          << what;
      ASSERT_EQ(0, std::memcmp(&got.rootBoxes[0], &expect.rootBoxes[0], sizeof(tsah::Aabb))) << what;
      ASSERT_EQ(blurred.downloadPositions(), instant.downloadPositions()) << what;
      const std::vector<tsah::WoopTriangle> woopGot = blurred.downloadWoop(), woopExpect = instant.downloadWoop();
      ASSERT_EQ(0, std::memcmp(woopGot.data(), woopExpect.data(), woopExpect.size() * sizeof(tsah::WoopTriangle)))
          << what;
      tsah::CpuRuntime cpu(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
      cpu.update(a.positionsAt(close));
      std::mt19937 rng(11);
      const std::vector<tsah::Ray> rays = tsah::test::randomRays(cpu.view(), a.triangleCount(), cpu.bounds(), 3000, rng);
      const std::vector<tsah::Hit> hitsGot = blurred.closestHits(rays), hitsExpect = instant.closestHits(rays);
      ASSERT_EQ(0, std::memcmp(hitsGot.data(), hitsExpect.data(), hitsExpect.size() * sizeof(tsah::Hit))) << what;
      // The next instant frame after the blurred one.
      const double next = t0 + 0.8 * span;
      blurred.updateAt(next);
      instant.updateAt(next);
      const tsah::FlatBvh nextGot = blurred.downloadTree(), nextExpect = instant.downloadTree();
      ASSERT_EQ(0, std::memcmp(nextGot.nodes.data(), nextExpect.nodes.data(),
                               nextExpect.nodes.size() * sizeof(tsah::GpuBvhNode)))
          << "next frame, " << what;
      const std::vector<tsah::WoopTriangle> nextWoop = blurred.downloadWoop(), nextWoopExpect = instant.downloadWoop();
      ASSERT_EQ(0, std::memcmp(nextWoop.data(), nextWoopExpect.data(), nextWoopExpect.size() * sizeof(tsah::WoopTriangle)))
          << "next frame, " << what;
    }
  }
}

TEST(CudaMotionBlurLayout, ADownloadNeedsABlurredFrame) {
  REQUIRE_GPU();
  const auto a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 800, 4);
  tc::GpuRuntime gpu(sahTree(a, 4), a);
  EXPECT_THROW(gpu.downloadBlurredLayout(), tsah::ConfigError);
  gpu.updateShutterAt(a.startTime(), a.endTime());
  EXPECT_NO_THROW(gpu.downloadBlurredLayout());
  gpu.updateAt(a.startTime());
  EXPECT_THROW(gpu.downloadBlurredLayout(), tsah::ConfigError);
}

}  // namespace

#else

TEST(CudaMotionBlurLayout, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
