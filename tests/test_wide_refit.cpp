// The wide refit: the SIMD Woop rows of every instruction set equal makeWoopTriangle bit for bit
// (degenerate triangles and padding lanes zero), and a refitted WideTree holds, for every leaf
// lane, exactly its triangle's rows and, for every child, exactly the union of its contents,
// however many threads refit it and whichever kernels compute the rows.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/layout/wide_tree.hpp"
#include "tsah/layout/woop.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

using tsah::SimdIsa;
using tsah::Vec3;
using tsah::WoopPacket;

bool sameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The refit's box rule: a coordinate that does not compare (NaN) is skipped. (Aabb::extend would
// keep a NaN that comes last.)
void extendSkippingNaN(tsah::Aabb& box, Vec3 p) {
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = p[a] < box.lo[a] ? p[a] : box.lo[a];
    box.hi[a] = p[a] > box.hi[a] ? p[a] : box.hi[a];
  }
}

// Random triangles of very different sizes and positions, with degenerate and NaN ones mixed in.
std::vector<std::array<Vec3, 3>> testTriangles(uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<std::array<Vec3, 3>> out;
  for (uint32_t i = 0; i < count; ++i) {
    const float scale = std::pow(10.0f, float(int(i % 9) - 4));  // 1e-4 .. 1e4
    const Vec3 c{u(rng) * 100.0f, u(rng) * 100.0f, u(rng) * 100.0f};
    std::array<Vec3, 3> t;
    for (Vec3& v : t) v = {c.x + scale * u(rng), c.y + scale * u(rng), c.z + scale * u(rng)};
    if (i % 7 == 3) t[2] = t[1];                               // two equal vertices
    if (i % 11 == 5) t[2] = t[0] + (t[1] - t[0]) * 0.5f;       // collinear
    if (i % 13 == 6) t[1] = t[2] = t[0];                       // a point
    if (i % 17 == 8) t[i % 3][i % 2] = std::numeric_limits<float>::quiet_NaN();  // a NaN coordinate
    out.push_back(t);
  }
  return out;
}

template <uint32_t N>
void checkRowKernel(SimdIsa isa) {
  const tsah::WideKernels& k = tsah::wideKernels(isa);
  void (*rows)(const float*, const uint32_t*, uint32_t, WoopPacket<N>&, tsah::Aabb&);
  if constexpr (N == 4)
    rows = k.woopRows4;
  else
    rows = k.woopRows8;
  ASSERT_NE(rows, nullptr) << tsah::name(isa);
  const auto tris = testTriangles(40 * N, 7);
  // Every triangle with its own three vertices, stored in reverse order so that ids, vertex
  // indices and slots all differ.
  const auto count = static_cast<uint32_t>(tris.size());
  std::vector<float> positions(9 * tris.size());
  std::vector<uint32_t> indices(3 * tris.size());
  for (uint32_t t = 0; t < count; ++t)
    for (int c = 0; c < 3; ++c) {
      const uint32_t vertex = 3 * (count - 1 - t) + c;
      indices[3 * t + c] = vertex;
      for (int a = 0; a < 3; ++a) positions[3 * vertex + a] = tris[t][c][a];
    }
  for (uint32_t first = 0; first + N <= count; first += N) {
    const uint32_t lanes = 1 + (first / N) % N;  // 1..N used lanes
    // The packet's triangle ids, scrambled; the lanes past `lanes` hold other triangles, which
    // neither the rows nor the box may show.
    uint32_t ids[N], vertices[3 * N];
    for (uint32_t lane = 0; lane < N; ++lane) {
      ids[lane] = (first + lane * 7 + (lane < lanes ? 0 : 5 * N)) % count;
      for (int c = 0; c < 3; ++c) vertices[3 * lane + c] = indices[3 * ids[lane] + c];
    }
    WoopPacket<N> pk;
    std::memset(&pk, 0xff, sizeof pk);  // rows must be overwritten, padding included
    tsah::Aabb box;
    rows(positions.data(), vertices, lanes, pk, box);
    tsah::Aabb expectedBox;  // of the used lanes only
    for (uint32_t lane = 0; lane < lanes; ++lane)
      for (const Vec3& p : tris[ids[lane]]) extendSkippingNaN(expectedBox, p);
    for (int a = 0; a < 3; ++a) {
      ASSERT_TRUE(sameBits(box.lo[a], expectedBox.lo[a])) << tsah::name(isa) << " N=" << N << " packet " << first;
      ASSERT_TRUE(sameBits(box.hi[a], expectedBox.hi[a])) << tsah::name(isa) << " N=" << N << " packet " << first;
    }
    for (uint32_t lane = 0; lane < N; ++lane) {
      const tsah::WoopTriangle expected =
          lane < lanes ? tsah::makeWoopTriangle(tris[ids[lane]][0], tris[ids[lane]][1], tris[ids[lane]][2])
                       : tsah::WoopTriangle{};
      const tsah::WoopTriangle got = pk.get(lane);
      const float* e = &expected.r0.x;
      const float* g = &got.r0.x;
      for (int r = 0; r < 12; ++r)
        ASSERT_TRUE(sameBits(e[r], g[r])) << tsah::name(isa) << " N=" << N << " triangle " << ids[lane]
                                          << " lane " << lane << " row value " << r << ": " << g[r] << " vs " << e[r];
    }
  }
}

TEST(WideRefit, PacketRowsOfEveryInstructionSetEqualMakeWoopTriangle) {
  for (SimdIsa isa : tsah::supportedIsas()) {
    checkRowKernel<4>(isa);
    checkRowKernel<8>(isa);
  }
}

// Every lane of every leaf packet holds its triangle's rows (padding lanes zero rows and the
// leaf's first slot), every child box the exact union of its triangles' vertices (NaN coordinates
// skipped, as Aabb::extend does) or of its child node's children, and the root box the union of
// the root's children.
template <uint32_t N>
void checkRefit(const tsah::WideTree<N>& tree, const float* p, const uint32_t* indices) {
  const auto nodes = tree.nodes();
  const auto packets = tree.packets();
  const auto triIndex = tree.triIndex();
  auto vertex = [&](uint32_t i) { return Vec3{p[3 * i], p[3 * i + 1], p[3 * i + 2]}; };
  for (const auto& node : nodes)
    for (uint32_t c = 0; c < N; ++c) {
      const tsah::Aabb box = node.childBox(c);
      if (node.ref[c] == 0 && node.count[c] == 0) continue;  // unused
      tsah::Aabb expected;
      if (tsah::isLeafRef(node.ref[c])) {
        const uint32_t first = tsah::leafFirstSlot(node.ref[c]);
        for (uint32_t i = 0; i < node.count[c]; ++i) {
          const WoopPacket<N>& pk = packets[first + i / N];
          const uint32_t* tri = indices + 3 * std::size_t(triIndex[pk.slot[i % N]]);
          const tsah::WoopTriangle w = tsah::makeWoopTriangle(vertex(tri[0]), vertex(tri[1]), vertex(tri[2]));
          const tsah::WoopTriangle got = pk.get(i % N);
          ASSERT_EQ(std::memcmp(&w, &got, sizeof w), 0) << "leaf lane " << i;
          for (int k = 0; k < 3; ++k) extendSkippingNaN(expected, vertex(tri[k]));
        }
        for (uint32_t i = node.count[c]; i % N != 0; ++i) {  // the last packet's padding lanes
          const WoopPacket<N>& pk = packets[first + i / N];
          const tsah::WoopTriangle got = pk.get(i % N);
          const tsah::WoopTriangle zero{};
          ASSERT_EQ(std::memcmp(&zero, &got, sizeof got), 0) << "padding lane " << i;
          ASSERT_EQ(pk.slot[i % N], packets[first].slot[0]) << "padding lane " << i;
        }
      } else {
        expected = nodes[static_cast<uint32_t>(node.ref[c])].bounds();
      }
      for (int a = 0; a < 3; ++a) {
        ASSERT_TRUE(sameBits(box.lo[a], expected.lo[a]));
        ASSERT_TRUE(sameBits(box.hi[a], expected.hi[a]));
      }
    }
  const tsah::Aabb root = nodes[0].bounds();
  for (int a = 0; a < 3; ++a) {
    ASSERT_TRUE(sameBits(tree.bounds().lo[a], root.lo[a]));
    ASSERT_TRUE(sameBits(tree.bounds().hi[a], root.hi[a]));
  }
}

// A tree in the Vertices form against the Woop-form tree of the same frame (checked by checkRefit):
// the same nodes bit for bit, and every lane of every vertex packet its triangle's vertices exactly
// (padding lanes those of the packet's lane 0).
template <uint32_t N>
void checkVertexRefit(const tsah::WideTree<N>& tree, const tsah::WideTree<N>& woop, const float* p,
                      const uint32_t* indices) {
  const auto nodes = tree.nodes(), woopNodes = woop.nodes();
  ASSERT_EQ(nodes.size(), woopNodes.size());
  ASSERT_EQ(std::memcmp(nodes.data(), woopNodes.data(), nodes.size_bytes()), 0);
  const auto packets = tree.vertexPackets();
  ASSERT_EQ(packets.size(), woop.packets().size());
  for (std::size_t pk = 0; pk < packets.size(); ++pk)
    for (uint32_t lane = 0; lane < N; ++lane) {
      // A used lane holds slot packetSlots[pk] + lane (the Woop packet names it); a padding lane
      // repeats lane 0 (its Woop slot is the leaf's first slot instead).
      const uint32_t first = tree.packetSlots()[pk];
      const uint32_t slot = woop.packets()[pk].slot[lane] == first + lane ? first + lane : first;
      const uint32_t* tri = indices + 3 * std::size_t(tree.triIndex()[slot]);
      for (uint32_t k = 0; k < 3; ++k) {
        const Vec3 got = packets[pk].get(k, lane);
        const float* v = p + 3 * std::size_t(tri[k]);
        ASSERT_TRUE(sameBits(got.x, v[0]) && sameBits(got.y, v[1]) && sameBits(got.z, v[2]))
            << "packet " << pk << " lane " << lane << " vertex " << k;
      }
    }
}

// Refits one tree frame after frame (so stale values of the previous frame would show), with a
// degenerate triangle and a NaN coordinate in the middle frame; in both triangle forms.
template <uint32_t N>
void refitWithEveryThreadCountAndIsa(const anim::Animation& a, const tsah::WideBvh& w) {
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  std::vector<std::vector<float>> frames;
  for (double t : {a.startTime(), 0.5 * (a.startTime() + a.endTime()), a.endTime()}) frames.push_back(a.positionsAt(t));
  std::vector<float>& middle = frames[1];
  for (int k = 0; k < 3; ++k) middle[3 * indices[3 * 10 + 1] + k] = middle[3 * indices[3 * 10] + k];  // triangle 10
  middle[3 * indices[3 * 20 + 2] + 1] = std::numeric_limits<float>::quiet_NaN();  // y of a vertex of triangle 20
  for (SimdIsa isa : tsah::supportedIsas())
    for (uint32_t threads : {1u, 3u, 16u}) {
      tsah::WideTree<N> tree(w, indices, threads, isa);
      tsah::WideTree<N> vertexTree(w, indices, threads, isa, tsah::TriangleForm::Vertices);
      const auto lastFirst = [](std::size_t n, const std::function<void(std::size_t, std::size_t)>& body) {
        for (std::size_t i = n; i-- > 0;) body(i, i + 1);  // tasks one by one, last first
      };
      for (std::size_t f = 0; f < frames.size(); ++f) {
        tree.refit(frames[f].data(), lastFirst);
        vertexTree.refit(frames[f].data(), lastFirst);
        SCOPED_TRACE(std::string(tsah::name(isa)) + " threads " + std::to_string(threads) + " frame " +
                     std::to_string(f));
        checkRefit(tree, frames[f].data(), indices.data());
        checkVertexRefit(vertexTree, tree, frames[f].data(), indices.data());
      }
    }
}

TEST(WideRefit, RefitHoldsExactRowsAndBoxesForEveryPlanAndInstructionSet) {
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 3000, 4);
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), a.positionsAt(a.startTime()), 1);
  const tsah::Bvh bvh = tsah::SweepSahBuilder().build(boxes.frame(0));
  for (uint32_t width : {4u, 8u}) {
    tsah::WideCollapser::Config c;
    c.width = width;
    c.leafPacket = width;
    const tsah::WideBvh w = tsah::WideCollapser(c).collapse(bvh);
    ASSERT_GT(w.nodeCount(), 20u);  // enough nodes for several refit tasks
    if (width == 4)
      refitWithEveryThreadCountAndIsa<4>(a, w);
    else
      refitWithEveryThreadCountAndIsa<8>(a, w);
  }
}

TEST(WideRefit, RejectsAnIndexArrayShorterThanTheTree) {
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 200, 1);
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), a.positionsAt(a.startTime()), 1);
  tsah::WideCollapser::Config c;
  c.width = 8;
  const tsah::WideBvh w = tsah::WideCollapser(c).collapse(tsah::SweepSahBuilder().build(boxes.frame(0)));
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  EXPECT_NO_THROW(tsah::WideTree<8>(w, indices, 1));
  const std::vector<uint32_t> shorter(indices.begin(), indices.end() - 3);  // the last triangle is missing
  EXPECT_THROW(tsah::WideTree<8>(w, shorter, 1), tsah::Error);
}

}  // namespace
