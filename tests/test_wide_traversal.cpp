// The wide layouts (bvh4, bvh8), with their triangles as Woop packets and as vertex packets
// (TriangleForm), against the binary traversal, for every instruction set this machine runs, each
// dispatch target tested explicitly: closest hit (same triangle, or a triangle at the same
// distance when two tie; distances equal to within 1e-6 relative, in fact bit-identical for Woop packets) and any hit
// (the same answer, in both child orders) on random and real scenes, plus the refit's boxes in every
// frame. A tie's triangle must lie on the ray at the hit's distance. Rays with a NaN or infinite
// component hit nothing.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <thread>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "test_support.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/woop.hpp"
#include "tsah/render/sampling.hpp"

namespace {

using tsah::test::generatedAnimation;

using tsah::Layout;
using tsah::SimdIsa;
using tsah::Vec3;

// A tree of frame 0 with the boxes of `frames` frames spread over the animation (what a .tbvh
// holds), so the wide collapse has several frames to weigh.
tsah::FlatBvh multiFrameTree(const anim::Animation& a, uint32_t maxLeaf, uint32_t frames) {
  std::vector<float> all;
  for (uint32_t f = 0; f < frames; ++f) {
    const double t = a.startTime() + (a.endTime() - a.startTime()) * f / std::max(1u, frames - 1);
    const auto p = a.positionsAt(t);
    all.insert(all.end(), p.begin(), p.end());
  }
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), all, frames);
  tsah::BinnedSahBuilder::Config c;
  c.maxLeafSize = maxLeaf;
  tsah::Bvh bvh = tsah::BinnedSahBuilder(c).build(boxes.frame(0));
  tsah::refit(bvh, boxes);
  return tsah::flattenBvh(bvh);
}

using tsah::TriangleForm;
constexpr TriangleForm kForms[] = {TriangleForm::Woop, TriangleForm::Vertices};
const char* formName(TriangleForm form) { return form == TriangleForm::Woop ? "woop" : "vertices"; }
// Tolerances against the binary traversal's Woop test: the Woop form gives its distances bit for
// bit; the vertex form's watertight test rounds differently, most where a ray grazes its triangle
// (the distance is then ill-conditioned in both tests; seen: 8e-6 at t = 0.0098), and its weights
// lose digits to the origin's distance from a small triangle (edge functions of vertices relative
// to the origin; seen: 1.4e-4).
float relativeT(TriangleForm form) { return form == TriangleForm::Woop ? 1e-6f : 1e-4f; }
float barycentricTolerance(TriangleForm form) { return form == TriangleForm::Woop ? 1e-6f : 1e-3f; }

tsah::CpuRuntime runtime(const anim::Animation& a, const tsah::FlatBvh& tree, Layout layout,
                         std::optional<SimdIsa> isa = std::nullopt, TriangleForm form = TriangleForm::Woop) {
  tsah::CpuRuntime::Config c;
  c.threads = 2;
  c.layout = layout;
  c.isa = isa;
  c.triangles = form;
  return tsah::CpuRuntime(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), c);
}

Vec3 randomUnit(std::mt19937& rng) {
  std::normal_distribution<float> g;
  return tsah::normalize(Vec3{g(rng), g(rng), g(rng)});
}

// Random rays of three kinds: from outside at triangles, from inside in any direction, and short
// occlusion-like rays leaving a triangle's surface (as ambient-occlusion rays do).
std::vector<tsah::Ray> randomRays(const tsah::CpuRuntime& rt, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  const tsah::Aabb b = rt.bounds();
  const float diag = std::sqrt(tsah::dot(b.extent(), b.extent()));
  std::uniform_real_distribution<float> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z), u01(0, 1);
  const float* p = rt.positions().data();
  auto vertex = [&](uint32_t i) { return Vec3{p[3 * i], p[3 * i + 1], p[3 * i + 2]}; };
  std::vector<tsah::Ray> rays(count);
  for (uint32_t i = 0; i < count; ++i) {
    tsah::Ray& ray = rays[i];
    const uint32_t* tri = rt.indices().data() + 3 * (rng() % rt.triangleCount());
    const float w0 = u01(rng), w1 = (1 - w0) * u01(rng);
    const Vec3 onTri = vertex(tri[0]) * w0 + vertex(tri[1]) * w1 + vertex(tri[2]) * (1 - w0 - w1);
    ray.tmin = 0.0f;
    ray.tmax = 3.4e38f;
    switch (i % 3) {
      case 0:
        ray.org = b.center() + randomUnit(rng) * diag;
        ray.dir = onTri + randomUnit(rng) * (0.01f * diag) - ray.org;
        break;
      case 1:
        ray.org = {ux(rng), uy(rng), uz(rng)};
        ray.dir = randomUnit(rng) * (0.1f + 3.0f * u01(rng));
        if (i % 4 == 1) ray.tmax = u01(rng) * 2.0f;
        break;
      default:
        ray.org = onTri + randomUnit(rng) * (1e-4f * diag);
        ray.dir = randomUnit(rng);
        ray.tmax = 0.1f * diag;
        break;
    }
  }
  return rays;
}

// Every wide (layout, instruction set) this machine runs.
std::vector<std::pair<Layout, SimdIsa>> wideTargets() {
  std::vector<std::pair<Layout, SimdIsa>> out;
  for (SimdIsa isa : tsah::supportedIsas()) {
    const tsah::WideKernels& k = tsah::wideKernels(isa);
    if (k.closest4) out.push_back({Layout::Bvh4, isa});
    if (k.closest8) out.push_back({Layout::Bvh8, isa});
  }
  return out;
}

// True when the hit's triangle lies on the ray at the hit's distance: a closest hit that names
// another triangle than the binary traversal's is a tie, never a triangle off the ray.
bool triangleOnRayAt(const tsah::CpuRuntime& rt, const tsah::Ray& ray, const tsah::Hit& h, float relative) {
  if (h.tri >= rt.triangleCount()) return false;
  const uint32_t* tri = rt.indices().data() + 3 * std::size_t(h.tri);
  const auto vertex = [&](uint32_t v) {
    return Vec3{rt.positions()[3 * v], rt.positions()[3 * v + 1], rt.positions()[3 * v + 2]};
  };
  tsah::RayPrep prep = tsah::prepareSlabs(ray);
  tsah::prepareShear(ray, prep);
  float t = 0.0f, u = 0.0f, v = 0.0f;
  return tsah::intersectWatertight(prep, vertex(tri[0]), vertex(tri[1]), vertex(tri[2]), ray.tmin, ray.tmax, t, u, v) &&
         std::abs(t - h.t) <= relative * std::max(1.0f, h.t);
}

// Traces the rays with the binary runtime and every wide target at times ts; counts the hits.
void checkSameHits(const anim::Animation& a, const tsah::FlatBvh& tree, std::span<const double> ts,
                   uint32_t rayCount, uint32_t seed, uint64_t& hits) {
  tsah::CpuRuntime binary = runtime(a, tree, Layout::Bvh2);
  hits = 0;
  for (const auto& [layout, isa] : wideTargets())
    for (TriangleForm form : kForms) {
      tsah::CpuRuntime wide = runtime(a, tree, layout, isa, form);
      EXPECT_EQ(wide.layoutInfo().isa, isa);
      for (double t : ts) {
        const auto positions = a.positionsAt(t);
        binary.update(positions);
        wide.update(positions);
        const tsah::Aabb bb = binary.bounds(), wb = wide.bounds();
        EXPECT_TRUE(bb.lo.x == wb.lo.x && bb.hi.y == wb.hi.y && bb.hi.z == wb.hi.z);
        const auto rays = randomRays(binary, rayCount, seed);
        for (std::size_t i = 0; i < rays.size(); ++i) {
          const tsah::Hit expect = binary.closestHit(rays[i]);
          const tsah::Hit got = wide.closestHit(rays[i]);
          const std::string where = std::string(tsah::name(layout)) + "/" + tsah::name(isa) + "/" + formName(form) +
                                    " ray " + std::to_string(i) + " t=" + std::to_string(t);
          ASSERT_EQ(expect.valid(), got.valid()) << where;
          ASSERT_EQ(binary.anyHit(rays[i]), wide.anyHit(rays[i])) << where;
          ASSERT_EQ(wide.anyHit(rays[i]), got.valid()) << where;
          ASSERT_EQ(wide.anyHit(rays[i], tsah::AnyHitOrder::TreeOrder), got.valid()) << where;
          if (!expect.valid()) continue;
          ++hits;
          ASSERT_NEAR(expect.t, got.t, relativeT(form) * std::max(1.0f, expect.t)) << where;
          if (expect.tri == got.tri) {
            ASSERT_NEAR(expect.u, got.u, barycentricTolerance(form)) << where;
            ASSERT_NEAR(expect.v, got.v, barycentricTolerance(form)) << where;
          } else {
            ASSERT_TRUE(triangleOnRayAt(binary, rays[i], got, relativeT(form)))
                << where << ": triangle " << got.tri << " is not on the ray";
          }
        }
      }
    }
}

uint64_t expectSameHits(const anim::Animation& a, const tsah::FlatBvh& tree, std::span<const double> ts,
                        uint32_t rayCount, uint32_t seed) {
  uint64_t hits = 0;
  checkSameHits(a, tree, ts, rayCount, seed, hits);
  return hits;
}

TEST(WideTraversal, EveryDispatchTargetIsTested) {
  const auto targets = wideTargets();
  ASSERT_FALSE(targets.empty());
  EXPECT_TRUE(tsah::isaSupported(SimdIsa::Sse));  // every x86-64
  EXPECT_EQ(tsah::bestIsa(), tsah::supportedIsas().back());
  EXPECT_TRUE(tsah::layoutSupported(tsah::fastestLayout()));
  for (SimdIsa isa : tsah::supportedIsas()) std::printf("dispatch target: %s\n", tsah::name(isa));
}

TEST(WideTraversal, SameHitsAsBinaryOnGeneratedAnimations) {
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    const auto a = generatedAnimation(kind, 1500, 8);
    const double ts[] = {a.startTime(), 0.5 * (a.startTime() + a.endTime()), a.endTime()};
    for (uint32_t leaf : {1u, 4u, 8u}) {
      const uint64_t hits = expectSameHits(a, multiFrameTree(a, leaf, 3), ts, 600, leaf);
      EXPECT_GT(hits, 300u);  // the rays must actually hit something
    }
  }
}

TEST(WideTraversal, SingleLeafTreesAndEmptyRays) {
  // Few triangles: the collapse may make the whole tree one leaf.
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 6, 2);
  const double ts[] = {a.startTime()};
  expectSameHits(a, multiFrameTree(a, 8, 2), ts, 300, 5);
  for (const auto& [layout, isa] : wideTargets()) {
    tsah::CpuRuntime rt = runtime(a, multiFrameTree(a, 8, 2), layout, isa);
    rt.update(a.positionsAt(a.startTime()));
    tsah::Ray away{rt.bounds().hi + Vec3{1, 1, 1}, 0.0f, {1, 1, 1}, 3.4e38f};
    EXPECT_FALSE(rt.closestHit(away).valid());
    EXPECT_FALSE(rt.anyHit(away));
    EXPECT_FALSE(rt.anyHit(away, tsah::AnyHitOrder::TreeOrder));
  }
}

TEST(WideTraversal, SameAnswersThroughEdgesAndVertices) {
  // Rays exactly through edges and vertices, where the watertight fallback decides: the wide
  // kernels must agree with the binary traversal (proven watertight in test_traversal).
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 800, 2);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 2);
  tsah::CpuRuntime binary = runtime(a, tree, Layout::Bvh2);
  binary.update(a.positionsAt(a.startTime()));
  for (const auto& [layout, isa] : wideTargets())
    for (TriangleForm form : kForms) {
      tsah::CpuRuntime rt = runtime(a, tree, layout, isa, form);
      rt.update(a.positionsAt(a.startTime()));
      const float* p = rt.positions().data();
      auto vertex = [&](uint32_t i) { return Vec3{p[3 * i], p[3 * i + 1], p[3 * i + 2]}; };
      const Vec3 eye = rt.bounds().center() + Vec3{0.3f, 3.0f, 0.5f};
      uint32_t hits = 0;
      for (uint32_t t = 0; t < rt.triangleCount(); ++t)
        for (int e = 0; e < 3; ++e) {
          const uint32_t* tri = rt.indices().data() + 3 * t;
          for (float s : {0.0f, 0.5f, 0.3f}) {
            const Vec3 target = vertex(tri[e]) * (1 - s) + vertex(tri[(e + 1) % 3]) * s;
            const tsah::Ray ray{eye, 0.0f, target - eye, 1.5f};
            const tsah::Hit expect = binary.closestHit(ray), got = rt.closestHit(ray);
            ASSERT_EQ(expect.valid(), got.valid())
                << tsah::name(isa) << "/" << formName(form) << " triangle " << t << " edge " << e;
            ASSERT_EQ(binary.anyHit(ray), rt.anyHit(ray));
            ASSERT_EQ(binary.anyHit(ray), rt.anyHit(ray, tsah::AnyHitOrder::TreeOrder));
            if (expect.valid()) {
              // A tie may pick a neighbour through the vertex.
              ASSERT_NEAR(expect.t, got.t, relativeT(form) * expect.t);
            }
            hits += got.valid() ? 1 : 0;
          }
        }
      EXPECT_GT(hits, rt.triangleCount() * 6);
    }
}

TEST(WideTraversal, AxisParallelRaysFarFromTheOriginHitAsTheBinaryTraversal) {
  // Axis-parallel rays have inv = +-1e30 on two axes (prepareSlabs's floor on tiny components), so
  // their slab distances on those axes are huge or infinite, and with the scene scaled to 1e9
  // org * inv leaves the float range; at 1e-3 and 1 it does not. Every box the binary traversal
  // enters must still be entered.
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 400, 2);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 2);
  for (float scale : {1e9f, 1e-3f, 1.0f}) {
    std::vector<float> positions = a.positionsAt(a.startTime());
    for (float& x : positions) x = x * scale + 3.0f * scale;  // away from the origin on every axis
    tsah::CpuRuntime binary = runtime(a, tree, Layout::Bvh2);
    binary.update(positions);
    for (const auto& [layout, isa] : wideTargets()) {
      tsah::CpuRuntime rt = runtime(a, tree, layout, isa);
      rt.update(positions);
      const Vec3 extent = rt.bounds().hi - rt.bounds().lo;
      const float diag = std::sqrt(tsah::dot(extent, extent));
      uint32_t hits = 0;
      for (uint32_t t = 0; t < rt.triangleCount(); ++t) {
        const uint32_t* tri = rt.indices().data() + 3 * t;
        Vec3 c{0, 0, 0};
        for (int k = 0; k < 3; ++k)
          c = c + Vec3{positions[3 * tri[k]], positions[3 * tri[k] + 1], positions[3 * tri[k] + 2]} * (1.0f / 3.0f);
        for (int axis = 0; axis < 3; ++axis)
          for (float sign : {1.0f, -1.0f}) {
            Vec3 dir{0, 0, 0};
            dir[axis] = sign;
            Vec3 org = c;
            org[axis] -= sign * diag;  // outside the scene, looking through the centroid
            const tsah::Ray ray{org, 0.0f, dir, 3.0f * diag};
            const tsah::Hit expect = binary.closestHit(ray), got = rt.closestHit(ray);
            const std::string where = std::string(tsah::name(layout)) + "/" + tsah::name(isa) + " scale " +
                                      std::to_string(scale) + " triangle " + std::to_string(t) + " axis " +
                                      std::to_string(axis);
            ASSERT_EQ(expect.valid(), got.valid()) << where;
            ASSERT_EQ(binary.anyHit(ray), rt.anyHit(ray)) << where;
            ASSERT_EQ(binary.anyHit(ray), rt.anyHit(ray, tsah::AnyHitOrder::TreeOrder)) << where;
            if (expect.valid()) {
              ASSERT_NEAR(expect.t, got.t, 1e-6f * expect.t) << where;
            }
            hits += got.valid() ? 1 : 0;
          }
      }
      EXPECT_GT(hits, rt.triangleCount());  // most centroid rays hit something
    }
  }
}

TEST(WideTraversal, RaysWithNanOrInfiniteValuesHitNothing) {
  // Their slab distances are NaN, which the node test's max and min drop: the wide kernels must
  // refuse them up front, or they enter unused child slots (a NaN origin walked off the stack).
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 400, 2);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 2);
  tsah::CpuRuntime binary = runtime(a, tree, Layout::Bvh2);
  binary.update(a.positionsAt(a.startTime()));
  const Vec3 inside = binary.bounds().center(), down{0.1f, -1.0f, 0.2f};
  const float nan = std::nanf(""), inf = std::numeric_limits<float>::infinity();
  std::vector<tsah::Ray> rays;
  for (int axis = 0; axis < 3; ++axis)
    for (float bad : {nan, inf, -inf}) {
      tsah::Ray fromBad{inside, 0.0f, down, 1e30f}, towardsBad{inside, 0.0f, down, 1e30f};
      fromBad.org[axis] = bad;
      towardsBad.dir[axis] = bad;
      rays.push_back(fromBad);
      rays.push_back(towardsBad);
    }
  rays.push_back({{nan, nan, nan}, 0.0f, down, 1e30f});
  rays.push_back({inside, nan, down, 1e30f});
  rays.push_back({inside, 0.0f, down, nan});
  for (const auto& [layout, isa] : wideTargets()) {
    tsah::CpuRuntime rt = runtime(a, tree, layout, isa);
    rt.update(a.positionsAt(a.startTime()));
    ASSERT_TRUE(rt.anyHit({inside, 0.0f, down, 1e30f}));  // the finite ray does hit
    for (std::size_t i = 0; i < rays.size(); ++i) {
      const std::string where = std::string(tsah::name(layout)) + "/" + tsah::name(isa) + " ray " + std::to_string(i);
      EXPECT_FALSE(rt.closestHit(rays[i]).valid()) << where;
      EXPECT_FALSE(rt.anyHit(rays[i])) << where;
      EXPECT_FALSE(rt.anyHit(rays[i], tsah::AnyHitOrder::TreeOrder)) << where;
      EXPECT_FALSE(binary.closestHit(rays[i]).valid()) << where;
    }
  }
}

// Every used child box of every node contains what is below it, after each update.
template <uint32_t N>
void expectBoxesContainChildren(const tsah::WideTree<N>& w, const tsah::CpuRuntime& rt) {
  const float* p = rt.positions().data();
  const auto nodes = w.nodes();
  for (std::size_t n = 0; n < nodes.size(); ++n)
    for (uint32_t c = 0; c < N; ++c) {
      const auto& node = nodes[n];
      if (node.ref[c] == 0 && node.count[c] == 0) continue;
      const tsah::Aabb box = node.childBox(c);
      if (!tsah::isLeafRef(node.ref[c])) {
        ASSERT_TRUE(box.contains(nodes[uint32_t(node.ref[c])].bounds())) << "node " << n << " child " << c;
        continue;
      }
      for (uint32_t i = 0; i < node.count[c]; ++i) {
        const uint32_t packet = tsah::leafFirstSlot(node.ref[c]) + i / N, lane = i % N;
        const uint32_t slot = w.packetSlots()[packet] + lane;
        if (w.form() == TriangleForm::Woop) {
          ASSERT_EQ(w.packets()[packet].slot[lane], slot);
        }
        const uint32_t* tri = rt.indices().data() + 3 * std::size_t(w.triIndex()[slot]);
        for (int k = 0; k < 3; ++k) {
          const Vec3 v{p[3 * tri[k]], p[3 * tri[k] + 1], p[3 * tri[k] + 2]};
          ASSERT_TRUE(v.x >= box.lo.x && v.x <= box.hi.x && v.y >= box.lo.y && v.y <= box.hi.y && v.z >= box.lo.z &&
                      v.z <= box.hi.z);
          if (w.form() == TriangleForm::Vertices) {  // the packet holds this frame's vertices exactly
            const Vec3 held = w.vertexPackets()[packet].get(uint32_t(k), lane);
            ASSERT_TRUE(held.x == v.x && held.y == v.y && held.z == v.z) << "packet " << packet << " lane " << lane;
          }
        }
      }
    }
}

TEST(WideTraversal, RefitBoxesContainChildrenInEveryFrameAndCostsAreReported) {
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 3000, 10);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 4);
  for (Layout layout : {Layout::Bvh4, Layout::Bvh8})
    for (TriangleForm form : kForms) {
      if (!tsah::layoutSupported(layout)) continue;
      tsah::CpuRuntime rt = runtime(a, tree, layout, std::nullopt, form);
      const auto* w4 = rt.wide4();
      const auto* w8 = rt.wide8();
      EXPECT_EQ(w4 ? w4->form() : w8->form(), form);
      EXPECT_EQ(w4 ? w4->packets().empty() : w8->packets().empty(), form == TriangleForm::Vertices);
      EXPECT_EQ(w4 ? w4->vertexPackets().size() : w8->vertexPackets().size(),
                form == TriangleForm::Vertices ? (w4 ? w4->packetCount() : w8->packetCount()) : 0u);
      EXPECT_GT(rt.layoutInfo().binaryCost, 0.0);
      EXPECT_LE(rt.layoutInfo().layoutCost, rt.layoutInfo().binaryCost);
      EXPECT_THROW(rt.view(), tsah::ConfigError);  // the binary tree is not refitted in a wide layout
      for (uint32_t f = 0; f < 10; ++f) {
        rt.update(a.positionsAt(a.startTime() + (a.endTime() - a.startTime()) * f / 9.0));
        if (layout == Layout::Bvh4)
          expectBoxesContainChildren(*rt.wide4(), rt);
        else
          expectBoxesContainChildren(*rt.wide8(), rt);
      }
    }
}

TEST(WideTraversal, RebuildKeepsTheLayout) {
  const auto a = generatedAnimation(anim::GeneratorKind::Swap, 1000, 4);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 2);
  tsah::CpuRuntime binary = runtime(a, tree, Layout::Bvh2);
  tsah::CpuRuntime wide = runtime(a, tree, tsah::fastestLayout());
  const auto positions = a.positionsAt(a.endTime());
  const auto builder = [](std::span<const tsah::Aabb> boxes) { return tsah::BinnedSahBuilder().build(boxes); };
  binary.rebuild(positions, builder);
  wide.rebuild(positions, builder);
  for (const tsah::Ray& ray : randomRays(binary, 500, 9)) {
    ASSERT_EQ(binary.closestHit(ray).valid(), wide.closestHit(ray).valid());
    ASSERT_EQ(binary.anyHit(ray), wide.anyHit(ray));
    ASSERT_EQ(binary.anyHit(ray), wide.anyHit(ray, tsah::AnyHitOrder::TreeOrder));
  }
}

TEST(WideTraversal, RejectsUnsupportedKernels) {
  const auto a = generatedAnimation(anim::GeneratorKind::Swap, 100, 2);
  EXPECT_THROW(runtime(a, multiFrameTree(a, 4, 1), Layout::Bvh8, SimdIsa::Sse), tsah::ConfigError);  // sse: 4-wide only
  // The binary layout has only Woop triangles.
  EXPECT_THROW(runtime(a, multiFrameTree(a, 4, 1), Layout::Bvh2, std::nullopt, TriangleForm::Vertices),
               tsah::ConfigError);
}

// A tree of vertex packets refitted only where its vertices move equals a full refit, packets
// included, and traces as the Woop form.
TEST(WideTraversal, VertexPacketsRefitOnlyWhatMoves) {
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 2000, 6);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 3);
  std::vector<uint32_t> moving;  // half of the vertices move; the others stay at their frame-0 place
  for (uint32_t v = 0; v < a.vertexCount(); v += 2) moving.push_back(v);
  const auto frame0 = a.positionsAt(a.startTime());
  for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
    if (!tsah::layoutSupported(layout)) continue;
    tsah::CpuRuntime::Config c(2);
    c.layout = layout;
    c.triangles = TriangleForm::Vertices;
    tsah::CpuRuntime full(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), c);
    c.movingVertices = moving;
    tsah::CpuRuntime part(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), c);
    tsah::CpuRuntime woop = runtime(a, tree, layout);
    for (double t : {a.startTime(), 0.4 * a.endTime(), a.endTime()}) {
      std::vector<float> p = a.positionsAt(t);
      for (uint32_t v = 1; v < a.vertexCount(); v += 2)
        for (int k = 0; k < 3; ++k) p[3 * v + k] = frame0[3 * v + k];
      full.update(p);
      part.update(p);
      woop.update(p);
      const auto bytes = [](const auto* w) {
        const auto nodes = w->nodes();
        const auto packets = w->vertexPackets();
        std::vector<uint8_t> out(nodes.size_bytes() + packets.size_bytes());
        std::memcpy(out.data(), nodes.data(), nodes.size_bytes());
        std::memcpy(out.data() + nodes.size_bytes(), packets.data(), packets.size_bytes());
        return out;
      };
      if (layout == Layout::Bvh4)
        EXPECT_EQ(bytes(full.wide4()), bytes(part.wide4())) << "t " << t;
      else
        EXPECT_EQ(bytes(full.wide8()), bytes(part.wide8())) << "t " << t;
      for (const tsah::Ray& ray : randomRays(woop, 400, 21)) {
        const tsah::Hit expect = woop.closestHit(ray), got = part.closestHit(ray);
        ASSERT_EQ(expect.valid(), got.valid());
        ASSERT_EQ(woop.anyHit(ray), part.anyHit(ray));
        if (expect.valid()) {
          ASSERT_NEAR(expect.t, got.t, relativeT(TriangleForm::Vertices) * std::max(1.0f, expect.t));
        }
      }
    }
  }
}

// A nested runtime's loops run in the arena of its caller, the others' in their own.
TEST(WideTraversal, NestedLoopsRunInTheCallersArena) {
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 200, 2);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 2);
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  tsah::CpuRuntime::Config c(1);
  tsah::CpuRuntime own(tree, indices, a.vertexCount(), c);
  c.nested = true;
  tsah::CpuRuntime nested(tree, indices, a.vertexCount(), c);
  const auto arenaSize = [](const tsah::CpuRuntime& rt) {
    int size = 0;
    rt.parallelFor(1, 1, [&](std::size_t, std::size_t) { size = tbb::this_task_arena::max_concurrency(); });
    return size;
  };
  tbb::task_arena caller(3);
  caller.execute([&] {
    EXPECT_EQ(arenaSize(nested), 3);
    EXPECT_EQ(arenaSize(own), 1);
  });
}

// Runtimes whose refits run nested in their callers' threads (Config::nested), three updated at
// once from their own threads, hold the same trees bit for bit as one with its own arena.
TEST(WideTraversal, NestedRefitsEqualRefitsInTheRuntimesOwnArena) {
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 3000, 6);
  const tsah::FlatBvh tree = multiFrameTree(a, 4, 3);
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  for (Layout layout : {Layout::Bvh4, Layout::Bvh8})
    for (TriangleForm form : kForms) {
      if (!tsah::layoutSupported(layout)) continue;
      tsah::CpuRuntime::Config c(4);
      c.layout = layout;
      c.triangles = form;
      tsah::CpuRuntime own(tree, indices, a.vertexCount(), c);
      c.nested = true;
      std::vector<std::unique_ptr<tsah::CpuRuntime>> nested;
      for (int i = 0; i < 3; ++i) nested.push_back(std::make_unique<tsah::CpuRuntime>(tree, indices, a.vertexCount(), c));
      const auto bytes = [&](const tsah::CpuRuntime& rt) {
        std::vector<uint8_t> out;
        const auto append = [&](auto span) {
          const auto* b = reinterpret_cast<const uint8_t*>(span.data());
          out.insert(out.end(), b, b + span.size_bytes());
        };
        if (layout == Layout::Bvh4) {
          append(rt.wide4()->nodes()), append(rt.wide4()->packets()), append(rt.wide4()->vertexPackets());
        } else {
          append(rt.wide8()->nodes()), append(rt.wide8()->packets()), append(rt.wide8()->vertexPackets());
        }
        return out;
      };
      for (double t : {a.startTime(), 0.6 * a.endTime()}) {
        const std::vector<float> p = a.positionsAt(t);
        own.update(p);
        std::vector<std::thread> threads;
        for (auto& rt : nested) threads.emplace_back([&rt, &p] { rt->update(p); });
        for (std::thread& th : threads) th.join();
        const std::vector<uint8_t> expect = bytes(own);
        for (const auto& rt : nested)
          ASSERT_EQ(bytes(*rt), expect) << tsah::name(layout) << " " << formName(form) << " t " << t;
      }
    }
}

TEST(WideTraversal, SameHitsAsBinaryOnRealScenes) {
  const auto dir = tsah::test::unpackedData("sequences/horse-gallop.tar.xz", "horse-gallop");
  if (dir.empty()) GTEST_SKIP() << "real data not available";
  const auto a = anim::load(dir.string());
  const double ts[] = {a.startTime(), 0.37 * (a.startTime() + a.endTime())};
  EXPECT_GT(expectSameHits(a, multiFrameTree(a, 8, 3), ts, 2000, 17), 500u);
  const auto faerie = tsah::test::dataDir() / "md2" / "faerie.md2";
  if (!std::filesystem::exists(faerie)) return;
  const auto b = anim::load(faerie.string());
  const double tb[] = {b.startTime(), b.endTime()};
  EXPECT_GT(expectSameHits(b, multiFrameTree(b, 4, 3), tb, 2000, 18), 300u);
}

}  // namespace
