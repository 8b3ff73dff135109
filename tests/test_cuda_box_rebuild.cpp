// The per-frame GPU rebuilds over given boxes (GpuRebuilder::enqueueBoxes, cuda_kernels/src/rebuild.hpp,
// the TLAS rebuild's input): built over the triangles' boxes they give the triangle build's tree, for
// both methods, with and without the leaf collapse, at several leaf sizes, for 1, 2 and many
// primitives and for equal boxes (the triangle build is its boxes then the box build: one copy of
// every step). Skipped without a device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <string>
#include <vector>

#include "rebuild.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;

// The triangles' boxes in vertex order (extendByTriangle's order, the same Aabb::extend).
std::vector<tsah::Aabb> triangleBoxes(const anim::Animation& a, const std::vector<float>& positions) {
  std::vector<tsah::Aabb> boxes(a.triangleCount());
  for (uint32_t t = 0; t < a.triangleCount(); ++t)
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = a.indices()[3 * std::size_t(t) + c];
      boxes[t].extend(tsah::Vec3{positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]});
    }
  return boxes;
}

// The same tree: nodes, leaves, primitive order, and boxes equal as floats (a zero's sign may differ
// between the host's and the device's min).
void expectSameTree(const tsah::Bvh& a, const tsah::Bvh& b) {
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  ASSERT_EQ(a.primIds, b.primIds);
  for (std::size_t n = 0; n < a.nodes.size(); ++n) {
    const tsah::BvhNode &x = a.nodes[n], &y = b.nodes[n];
    ASSERT_EQ(x.parent, y.parent) << "node " << n;
    ASSERT_EQ(x.left, y.left) << "node " << n;
    ASSERT_EQ(x.right, y.right) << "node " << n;
    ASSERT_EQ(x.primBegin, y.primBegin) << "node " << n;
    ASSERT_EQ(x.primCount, y.primCount) << "node " << n;
    const tsah::Aabb &p = a.boxes[n], &q = b.boxes[n];
    EXPECT_TRUE(p.lo.x == q.lo.x && p.lo.y == q.lo.y && p.lo.z == q.lo.z && p.hi.x == q.hi.x && p.hi.y == q.hi.y &&
                p.hi.z == q.hi.z)
        << "node " << n;
  }
}

void checkBoxBuildEqualsTriangleBuild(const anim::Animation& a, double t) {
  const std::vector<float> positions = a.positionsAt(t);
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  const tc::DeviceBuffer<uint32_t> deviceIndices{std::span<const uint32_t>(indices)};
  const tc::DeviceBuffer<float> devicePositions{std::span<const float>(positions)};
  const std::vector<tsah::Aabb> boxes = triangleBoxes(a, positions);
  const tc::DeviceBuffer<tsah::Aabb> deviceBoxes{std::span<const tsah::Aabb>(boxes)};
  tc::detail::GpuRebuilder fromTriangles(a.triangleCount(), tsah::Layout::Bvh2);
  tc::detail::GpuRebuilder fromBoxes(a.triangleCount(), tsah::Layout::Bvh2);
  for (auto method : {tc::RebuildMethod::Lbvh, tc::RebuildMethod::HlbvhSah})
    for (const bool collapse : {false, true})
      for (const uint32_t leaf : {1u, 4u, 8u}) {
        SCOPED_TRACE(std::string(tc::rebuildMethodName(method)) + (collapse ? " collapsed" : " bare") + ", leaves of " +
                     std::to_string(leaf) + ", " + std::to_string(a.triangleCount()) + " triangles");
        tc::RebuildOptions o;
        o.method = method;
        o.collapse = collapse;
        o.maxLeafSize = leaf;
        o.woop = false;
        const tc::RebuildTimings tri = fromTriangles.build(deviceIndices.data(), devicePositions.data(), o, nullptr, nullptr);
        fromBoxes.enqueueBoxes(deviceBoxes.data(), o, nullptr);
        const tc::RebuildTimings box = fromBoxes.collect(o);
        EXPECT_EQ(box.interiorNodes, tri.interiorNodes);
        EXPECT_EQ(box.leaves, tri.leaves);
        EXPECT_EQ(box.depth, tri.depth);
        EXPECT_EQ(box.clusters, tri.clusters);
        const tsah::Bvh built = fromBoxes.download(nullptr);
        expectSameTree(built, fromTriangles.download(nullptr));
        tsah::PrimitiveBoxes prims;
        prims.frameCount = 1;
        prims.primCount = a.triangleCount();
        prims.boxes = boxes;
        EXPECT_EQ(tsah::validate(built, &prims), std::nullopt);
      }
}

TEST(CudaBoxRebuild, BuildsOverTriangleBoxesGiveTheTriangleBuildsTree) {
  REQUIRE_GPU();
  const uint32_t big = tsah::test::shortCudaRun() ? 3000 : 20000;
  for (auto kind : {anim::GeneratorKind::Wave, anim::GeneratorKind::Explode}) {
    const anim::Animation a = tsah::test::generatedAnimation(kind, big, 3, 11);
    checkBoxBuildEqualsTriangleBuild(a, a.startTime());
    checkBoxBuildEqualsTriangleBuild(a, 0.7 * a.endTime());
  }
  // 1, 2 and 9 triangles of a wave, and one triangle 300 times (equal Morton codes).
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 500, 2, 5);
  const std::vector<float> start = wave.positionsAt(0.0);
  for (const uint32_t tiny : {1u, 2u, 9u}) {
    std::vector<uint32_t> indices(wave.indices().begin(), wave.indices().begin() + 3 * tiny);
    checkBoxBuildEqualsTriangleBuild(anim::Animation(std::move(indices), wave.vertexCount(), start, {0.0}), 0.0);
  }
  std::vector<uint32_t> same;
  for (uint32_t i = 0; i < 300; ++i) same.insert(same.end(), {i % 3, (i + 1) % 3, (i + 2) % 3});
  checkBoxBuildEqualsTriangleBuild(anim::Animation(std::move(same), 3, {0, 0, 0, 1, 0, 0, 0, 1, 0}, {0.0}), 0.0);
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
