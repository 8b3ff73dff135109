#pragma once
// The blurred-frame checks shared by the motion-blur and moving-refit tests: every key set of two
// CPU runtimes compared bit for bit.
#include <gtest/gtest.h>

#include <cstring>
#include <span>
#include <string>

#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah::test {

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
