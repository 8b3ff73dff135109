// The static/moving split of anim::Animation and .tanim version 2 (static vertices stored once).
#include <gtest/gtest.h>

#include <cstring>

#include "anim/animation.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "anim/tanim.hpp"

namespace {

// A 100-vertex strip: vertices 0..89 never move, 90..99 move along x over 4 keyframes.
anim::Animation mostlyStatic() {
  const uint32_t vertices = 100, frames = 4;
  std::vector<uint32_t> idx;
  for (uint32_t v = 0; v + 2 < vertices; ++v) idx.insert(idx.end(), {v, v + 1, v + 2});
  std::vector<float> pos;
  for (uint32_t k = 0; k < frames; ++k)
    for (uint32_t v = 0; v < vertices; ++v) {
      const float dx = v >= 90 ? 0.5f * float(k) * float(v - 89) : 0.0f;
      pos.insert(pos.end(), {float(v) + dx, float(v % 2), -0.0f});
    }
  return anim::Animation(idx, vertices, pos, {0.0, 1.0, 2.0, 4.0}, "strip");
}

// The reference: every keyframe whole, the moving vertices (90..99) blended the dense way, the
// static ones exactly at rest (a blend of two equal floats may round away from them).
std::vector<float> denseAt(const std::vector<float>& all, uint32_t vertices, std::span<const double> times, double t) {
  const auto [k, alpha] = anim::keyframeBlend(times, t);
  const std::size_t n = std::size_t(vertices) * 3;
  std::vector<float> out(n);
  for (std::size_t i = 0; i < n; ++i)
    out[i] = alpha == 0.0f || i < 90 * 3 ? all[k * n + i] : (1.0f - alpha) * all[k * n + i] + alpha * all[(k + 1) * n + i];
  return out;
}

TEST(StaticVertices, FoundAndStoredOnce) {
  const auto a = mostlyStatic();
  EXPECT_EQ(a.movingVertexCount(), 10u);
  EXPECT_EQ(a.staticVertexCount(), 90u);
  ASSERT_EQ(a.movingVertices().size(), 10u);
  EXPECT_EQ(a.movingVertices().front(), 90u);
  EXPECT_EQ(a.motion().size(), 4u * 10 * 3);
  EXPECT_EQ(a.memoryBytes(), anim::Animation::memoryBytesFor(98, 100, 10, 4));
  EXPECT_LT(a.memoryBytes(), 98u * 12 + 4u * 100 * 12);  // less than every keyframe whole
}

TEST(StaticVertices, PositionsEqualTheDenseInterpolation) {
  const auto a = mostlyStatic();
  std::vector<float> all;
  for (uint32_t k = 0; k < 4; ++k) {
    const auto f = a.keyframe(k);
    all.insert(all.end(), f.begin(), f.end());
  }
  EXPECT_EQ(all, a.allPositions());
  EXPECT_EQ(a.keyframe(3)[3 * 99], 99.0f + 0.5f * 3 * 10);
  std::vector<float> running = a.positionsAt(0.0);  // then only the moving ones per frame
  for (double t : {-1.0, 0.0, 0.3, 1.0, 1.5, 2.7, 4.0, 9.0}) {
    const auto ref = denseAt(all, 100, a.times(), t);
    const auto p = a.positionsAt(t);
    EXPECT_EQ(0, std::memcmp(ref.data(), p.data(), p.size() * 4)) << t;  // bitwise, -0 kept
    a.movingPositionsAt(t, running);
    EXPECT_EQ(0, std::memcmp(ref.data(), running.data(), p.size() * 4)) << t;
  }
  const auto b = a.bounds();
  EXPECT_FLOAT_EQ(b.max[0], 99.0f + 0.5f * 3 * 10);
  EXPECT_FLOAT_EQ(a.keyframeBounds(0).max[0], 99.0f);
}

TEST(StaticVertices, ResampleAndSegmentKeepTheSplit) {
  const auto a = mostlyStatic();
  const auto r = a.resample(7);
  EXPECT_EQ(r.movingVertexCount(), 10u);
  for (double t : r.times()) EXPECT_EQ(r.positionsAt(t), a.positionsAt(t)) << t;
  const auto s = a.segment(0.5, 3.0);
  EXPECT_EQ(s.movingVertexCount(), 10u);
  EXPECT_EQ(s.positionsAt(1.7), a.positionsAt(1.7));
}

TEST(StaticVertices, AllMovingKeepsTheDenseForm) {
  std::vector<float> pos{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1};
  const anim::Animation a({0, 1, 2}, 3, pos, {0.0, 1.0});
  EXPECT_TRUE(a.allMoving());
  EXPECT_TRUE(a.movingVertices().empty());
  EXPECT_TRUE(a.restPositions().empty());
  EXPECT_EQ(a.allPositions(), pos);
}

TEST(StaticVertices, WithStaticVerticesChecksItsInput) {
  EXPECT_THROW(anim::Animation::withStaticVertices({0, 1, 2}, std::vector<float>(9, 0.0f), {2, 1},
                                                   std::vector<float>(6, 0.0f), {0.0}),
               tsah::FileError);  // ids not ascending
  EXPECT_THROW(anim::Animation::withStaticVertices({0, 1, 2}, std::vector<float>(9, 0.0f), {1},
                                                   std::vector<float>(5, 0.0f), {0.0}),
               tsah::FileError);  // motion size
  const auto a = anim::Animation::withStaticVertices({0, 1, 2}, {0, 0, 0, 1, 0, 0, 0, 1, 0}, {1},
                                                     {1, 0, 0, 3, 0, 0}, {0.0, 2.0});
  EXPECT_EQ(a.positionsAt(1.0), (std::vector<float>{0, 0, 0, 2, 0, 0, 0, 1, 0}));
}

TEST(TanimVersion2, RoundTripKeepsTheSplitAndIsSmaller) {
  const auto a = mostlyStatic();
  const auto bytes = anim::encodeTanim(a);
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  EXPECT_EQ(version, 2u);
  EXPECT_LT(bytes.size(), 64u + 4 * 100 * 12);
  const auto b = anim::decodeTanim(bytes, "mem.tanim");
  EXPECT_EQ(b.movingVertexCount(), 10u);
  EXPECT_EQ(b.allPositions(), a.allPositions());
  EXPECT_EQ(std::vector<double>(b.times().begin(), b.times().end()),
            std::vector<double>(a.times().begin(), a.times().end()));
}

// A version 1 file written by hand (header + dense payload) still reads.
TEST(TanimVersion2, ReadsVersion1) {
  const auto a = mostlyStatic();
  const std::vector<float> all = a.allPositions();
  tsah::ByteWriter payload;
  payload.append("strip\0\0\0", 8);
  payload.writeArray(a.times());
  payload.writeArray(a.indices());
  payload.writeArray(std::span<const float>(all));
  struct Header {
    char magic[8];
    uint32_t version, flags, vertexCount, triangleCount, keyframeCount, cameraKeyCount, nameBytes, reserved;
    uint64_t payloadBytes;
    uint32_t payloadCrc, reserved2[2], headerCrc;
  } h{};
  static_assert(sizeof(Header) == 64);
  std::memcpy(h.magic, "TSAHANIM", 8);
  h.version = 1;
  h.vertexCount = 100;
  h.triangleCount = 98;
  h.keyframeCount = 4;
  h.nameBytes = 5;
  h.payloadBytes = payload.buffer().size();
  h.payloadCrc = tsah::crc32(payload.buffer().data(), payload.buffer().size());
  h.headerCrc = tsah::crc32(&h, 60);
  tsah::ByteWriter file;
  file.write(h);
  file.append(payload.buffer().data(), payload.buffer().size());
  const auto b = anim::decodeTanim(file.buffer(), "v1.tanim");
  EXPECT_EQ(b.allPositions(), all);
  EXPECT_EQ(b.movingVertexCount(), 10u);  // found on reading
  EXPECT_EQ(b.name(), "strip");
}

TEST(TanimVersion2, RejectsMoreMovingThanVertices) {
  auto bytes = anim::encodeTanim(mostlyStatic());
  const uint32_t absurd = 1000;
  std::memcpy(bytes.data() + 36, &absurd, 4);
  const uint32_t crc = tsah::crc32(bytes.data(), 60);
  std::memcpy(bytes.data() + 60, &crc, 4);
  EXPECT_THROW(anim::decodeTanim(bytes, "bad.tanim"), tsah::FileError);
}

}  // namespace
