#pragma once
// The blurred-frame checks shared by the motion-blur and moving-refit tests: the layouts to run
// them in, the triangles of a blurred frame at a time and its brute-force hit, and every key set of
// two CPU runtimes compared bit for bit.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/woop.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "test_support.hpp"

namespace tsah::test {

// Rays aimed at the scene as the runtime's positions place it (any layout).
inline std::vector<Ray> raysAtRuntime(const CpuRuntime& rt, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  BvhView v;
  v.indices = rt.indices().data();
  v.positions = rt.positions().data();
  return randomRays(v, rt.triangleCount(), rt.bounds(), count, rng);
}

// A layout and, for the wide ones, the kernels' instruction set.
struct LayoutCase {
  Layout layout = Layout::Bvh2;
  SimdIsa isa = SimdIsa::Sse;
};

// bvh2, and bvh4 / bvh8 with every instruction set this machine runs.
inline std::vector<LayoutCase> layoutCases() {
  std::vector<LayoutCase> all{{Layout::Bvh2, SimdIsa::Sse}};
  for (SimdIsa isa : {SimdIsa::Sse, SimdIsa::Avx2, SimdIsa::Avx512}) {
    if (!isaSupported(isa)) continue;
    all.push_back({Layout::Bvh4, isa});
    if (isa != SimdIsa::Sse) all.push_back({Layout::Bvh8, isa});
  }
  return all;
}

inline std::string describe(const LayoutCase& c) {
  return std::string(name(c.layout)) + (c.layout == Layout::Bvh2 ? "" : std::string(" ") + name(c.isa));
}

// The triangles of a blurred frame at a time: positions at its keys (shutter fractions), lerped.
struct KeyedGeometry {
  std::vector<float> fractions;
  std::vector<std::vector<float>> positions;
  Vec3 vertex(uint32_t i, float time) const {
    const motion::Segment seg = motion::segmentAt(fractions.data(), int(fractions.size()), time);
    const float* p0 = positions[seg.index].data() + 3 * std::size_t(i);
    const float* p1 = positions[seg.index + 1].data() + 3 * std::size_t(i);
    return motion::lerpVertex({p0[0], p0[1], p0[2]}, {p1[0], p1[1], p1[2]}, seg.f);
  }
};

// The nearest hit of the runtime's triangles lerped at the ray's time (brute force).
inline Hit bruteForce(const CpuRuntime& rt, const KeyedGeometry& g, float time, const Ray& ray) {
  const RayPrep prep = prepareRay(ray);
  Hit best;
  float tmax = ray.tmax;
  const auto idx = rt.indices();
  for (uint32_t tri = 0; tri < rt.triangleCount(); ++tri) {
    float t, u, v;
    if (intersectWatertight(prep, g.vertex(idx[3 * tri], time), g.vertex(idx[3 * tri + 1], time),
                            g.vertex(idx[3 * tri + 2], time), ray.tmin, tmax, t, u, v)) {
      best = Hit{t, u, v, tri};
      tmax = t;
    }
  }
  return best;
}

// Every key set of a blurred runtime, its positions and bounds (the last key's), bit for bit.
inline void expectSameShutter(const CpuRuntime& a, const CpuRuntime& b) {
  const auto same = [](const auto& x, const auto& y) {
    const std::span sx(x), sy(y);
    return sx.size() == sy.size() && (sx.empty() || std::memcmp(sx.data(), sy.data(), sx.size_bytes()) == 0);
  };
  ASSERT_TRUE(same(a.keyTimes(), b.keyTimes()));
  const std::size_t keys = a.keyTimes().size(), floats = 3 * std::size_t(a.vertexCount());
  const MotionBvhView &va = a.motionView(), &vb = b.motionView();
  EXPECT_TRUE(same(std::span(va.keyPositions, keys * floats), std::span(vb.keyPositions, keys * floats)));
  EXPECT_TRUE(same(std::span(va.keyRootBoxes, keys), std::span(vb.keyRootBoxes, keys)));
  EXPECT_TRUE(same(std::span(va.keyNodes, keys * va.nodeCount), std::span(vb.keyNodes, keys * vb.nodeCount)));
  for (std::size_t k = 0; k < keys; ++k) {
    SCOPED_TRACE("key " + std::to_string(k));
    EXPECT_TRUE(same(a.keyWideNodes4(k), b.keyWideNodes4(k)));
    EXPECT_TRUE(same(a.keyVertexPackets4(k), b.keyVertexPackets4(k)));
    EXPECT_TRUE(same(a.keyWideNodes8(k), b.keyWideNodes8(k)));
    EXPECT_TRUE(same(a.keyVertexPackets8(k), b.keyVertexPackets8(k)));
  }
  if (a.wide4()) {
    EXPECT_FALSE(a.keyVertexPackets4(keys - 1).empty());
  }
  if (a.wide8()) {
    EXPECT_FALSE(a.keyVertexPackets8(keys - 1).empty());
  }
  EXPECT_TRUE(same(a.positions(), b.positions()));
  const Aabb ba = a.bounds(), bb = b.bounds();
  EXPECT_EQ(std::memcmp(&ba, &bb, sizeof(Aabb)), 0);
}

}  // namespace tsah::test
