#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/tanim.hpp"
#include "test_support.hpp"

namespace {

anim::Animation sample() {
  anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 300, 4, 7);
  anim::CameraKey k;
  k.time = 1.5;
  k.eye = {1, 2, 3};
  k.fovyDegrees = 50;
  a.setCameraPath({k});
  return a;
}

void expectSame(const anim::Animation& a, const anim::Animation& b) {
  EXPECT_EQ(a.name(), b.name());
  ASSERT_EQ(a.vertexCount(), b.vertexCount());
  ASSERT_EQ(a.triangleCount(), b.triangleCount());
  ASSERT_EQ(a.keyframeCount(), b.keyframeCount());
  EXPECT_TRUE(std::equal(a.indices().begin(), a.indices().end(), b.indices().begin()));
  EXPECT_TRUE(std::equal(a.times().begin(), a.times().end(), b.times().begin()));
  EXPECT_EQ(a.allPositions(), b.allPositions());
  ASSERT_EQ(a.cameraPath().size(), b.cameraPath().size());
  for (std::size_t i = 0; i < a.cameraPath().size(); ++i) {
    EXPECT_EQ(a.cameraPath()[i].time, b.cameraPath()[i].time);
    EXPECT_EQ(a.cameraPath()[i].eye, b.cameraPath()[i].eye);
    EXPECT_EQ(a.cameraPath()[i].fovyDegrees, b.cameraPath()[i].fovyDegrees);
  }
}

TEST(Crc32, KnownValue) {
  EXPECT_EQ(tsah::crc32("123456789", 9), 0xCBF43926u);
  // Continuing a CRC over two pieces equals the CRC of the whole.
  EXPECT_EQ(tsah::crc32("6789", 4, tsah::crc32("12345", 5)), 0xCBF43926u);
  // An empty piece (a null pointer, as an empty vector's data()) leaves the CRC as it was.
  EXPECT_EQ(tsah::crc32(nullptr, 0, tsah::crc32("123456789", 9)), 0xCBF43926u);
  EXPECT_EQ(tsah::crc32(nullptr, 0), 0u);
  // Two pieces' CRCs computed apart combine into the whole's.
  EXPECT_EQ(tsah::crc32Combine(tsah::crc32("123", 3), tsah::crc32("456789", 6), 6), 0xCBF43926u);
  EXPECT_EQ(tsah::crc32Combine(tsah::crc32("123456789", 9), 0u, 0), 0xCBF43926u);
  const std::string big(1 << 20, 'x');
  EXPECT_EQ(tsah::crc32Combine(tsah::crc32("12", 2), tsah::crc32(big.data(), big.size()), big.size()),
            tsah::crc32(big.data(), big.size(), tsah::crc32("12", 2)));
}

TEST(Tanim, RoundTripInMemoryAndOnDisk) {
  const auto a = sample();
  const auto bytes = anim::encodeTanim(a);
  expectSame(a, anim::decodeTanim(bytes, "mem"));
  const auto path = (tsah::test::scratchDir() / "a.tanim").string();
  anim::saveTanim(a, path);
  expectSame(a, anim::loadTanim(path));
  // The atomic writer leaves no temporary behind.
  std::size_t files = 0;
  for ([[maybe_unused]] auto& e : std::filesystem::directory_iterator(std::filesystem::path(path).parent_path())) ++files;
  EXPECT_EQ(files, 1u);
}

TEST(Tanim, EveryTruncationIsRejected) {
  const auto bytes = anim::encodeTanim(sample());
  for (std::size_t n = 0; n < bytes.size(); n += 1 + n / 16) {
    std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + std::ptrdiff_t(n));
    EXPECT_THROW(anim::decodeTanim(cut, "cut.tanim"), tsah::FileError) << "length " << n;
  }
}

TEST(Tanim, CorruptionIsDetected) {
  const auto bytes = anim::encodeTanim(sample());
  uint64_t state = 12345;
  for (int trial = 0; trial < 2000; ++trial) {
    auto copy = bytes;
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    const std::size_t at = (state >> 33) % copy.size();
    copy[at] ^= uint8_t(1u << ((state >> 20) % 8));
    EXPECT_THROW(anim::decodeTanim(copy, "flip.tanim"), tsah::FileError) << "byte " << at;
  }
}

TEST(Tanim, HostileCountsWithValidChecksumsAreRejectedWithoutHugeAllocation) {
  auto bytes = anim::encodeTanim(sample());
  // Patch the vertex count to an absurd value and recompute the header CRC, as an attacker would.
  uint32_t absurd = 0xfffffff0u;
  std::memcpy(bytes.data() + 16, &absurd, 4);
  const uint32_t crc = tsah::crc32(bytes.data(), 60);
  std::memcpy(bytes.data() + 60, &crc, 4);
  try {
    anim::decodeTanim(bytes, "hostile.tanim");
    FAIL();
  } catch (const tsah::FileError& e) {
    EXPECT_NE(std::string(e.what()).find("hostile.tanim"), std::string::npos);
  }
}

TEST(Tanim, MissingFileAndWrongMagic) {
  EXPECT_THROW(anim::loadTanim("/nonexistent/x.tanim"), tsah::FileError);
  std::vector<uint8_t> junk(200, 'x');
  EXPECT_THROW(anim::decodeTanim(junk, "junk.tanim"), tsah::FileError);
}

}  // namespace

// Fuzz finding (fuzz_tanim): a stored name with a line break made a two-line error. Readers refuse
// control characters in the name, writers replace them, and consistency errors name the file.
TEST(Tanim, NameWithControlCharactersIsRefusedAndNeverWritten) {
  anim::Animation a = sample();
  a.setName("two\nlines");
  std::vector<uint8_t> bytes = anim::encodeTanim(a);
  EXPECT_EQ(anim::decodeTanim(bytes, "w.tanim").name(), "two_lines");
  bytes[64 + 3] = '\n';  // the name starts the payload; repair both checksums as a hostile file would
  const uint32_t payloadCrc = tsah::crc32(bytes.data() + 64, bytes.size() - 64);
  std::memcpy(bytes.data() + 48, &payloadCrc, 4);
  const uint32_t headerCrc = tsah::crc32(bytes.data(), 60);
  std::memcpy(bytes.data() + 60, &headerCrc, 4);
  try {
    anim::decodeTanim(bytes, "n.tanim");
    FAIL() << "accepted a name with a line break";
  } catch (const tsah::FileError& e) {
    EXPECT_STREQ(e.what(), "n.tanim: the animation name holds a control character (byte 10 at 3)");
  }
}

// Camera keys with NaN or infinite vectors, or times that do not increase, are refused naming the
// file and the key (not left for the camera maths of `tsah trace` to trip over).
TEST(Tanim, BadCameraKeysAreRefusedNamingTheFile) {
  auto refusal = [](std::vector<anim::CameraKey> keys) -> std::string {
    anim::Animation a = sample();
    a.setCameraPath(std::move(keys));
    try {
      anim::decodeTanim(anim::encodeTanim(a), "cam.tanim");
    } catch (const tsah::FileError& e) {
      return e.what();
    }
    return "accepted";
  };
  anim::CameraKey first, second;
  second.time = 1.0;
  EXPECT_EQ(refusal({first, second}), "accepted");
  anim::CameraKey nanEye = second;
  nanEye.eye[1] = std::nanf("");
  EXPECT_EQ(refusal({first, nanEye}), "cam.tanim: camera key 1 has a non-finite eye");
  anim::CameraKey infUp = first;
  infUp.up[2] = INFINITY;
  EXPECT_EQ(refusal({infUp}), "cam.tanim: camera key 0 has a non-finite up vector");
  EXPECT_EQ(refusal({second, first}), "cam.tanim: camera key 1 time 0.000000 is not after the previous key's (1.000000)");
  EXPECT_EQ(refusal({first, first}), "cam.tanim: camera key 1 time 0.000000 is not after the previous key's (0.000000)");
}
