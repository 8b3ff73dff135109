// The memory budget (tsah/base/memory.hpp): a share of what is available, not all of it, capped by
// TSAH_MEMORY_LIMIT_MB, and the statements that use it (the renderer's frame buffers).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "anim/generators.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "test_support.hpp"

namespace {

std::size_t memAvailableBytes() {
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  std::size_t kib = 0;
  std::string line;
  while (std::getline(meminfo, line)) {
    std::istringstream fields(line);
    if (fields >> key >> kib && key == "MemAvailable:") return kib * 1024;
  }
  return 0;
}

// Sets TSAH_MEMORY_LIMIT_MB for the scope of one test.
class MemoryLimit {
 public:
  explicit MemoryLimit(const char* mib) {
    if (const char* old = std::getenv("TSAH_MEMORY_LIMIT_MB")) saved_ = old, had_ = true;
    if (mib) ::setenv("TSAH_MEMORY_LIMIT_MB", mib, 1);
    else ::unsetenv("TSAH_MEMORY_LIMIT_MB");
  }
  ~MemoryLimit() {
    if (had_) ::setenv("TSAH_MEMORY_LIMIT_MB", saved_.c_str(), 1);
    else ::unsetenv("TSAH_MEMORY_LIMIT_MB");
  }

 private:
  std::string saved_;
  bool had_ = false;
};

std::string failureOf(std::size_t bytes) {
  try {
    tsah::checkFitsInMemory(bytes, "who", "what");
  } catch (const tsah::Failure& e) {
    return e.what();
  }
  return "";
}

TEST(MemoryBudget, LeavesHeadroomBelowWhatIsAvailable) {
  const MemoryLimit none(nullptr);
  const std::size_t available = memAvailableBytes();
  ASSERT_GT(available, 0u) << "/proc/meminfo has no MemAvailable";
  // MemAvailable moves between the two reads: a few percent of slack, far from "all of it".
  EXPECT_LE(double(tsah::availableMemoryBytes()), 0.80 * double(available));
  EXPECT_GE(double(tsah::availableMemoryBytes()), 0.70 * double(available));
  // A request of 90% of what is free is refused, and the message says where the budget comes from.
  const std::string message = failureOf(std::size_t(0.9 * double(available)));
  EXPECT_NE(message.find("MiB of memory available (75% of the "), std::string::npos) << message;
}

TEST(MemoryBudget, TheLimitCapsTheBudget) {
  const MemoryLimit one("1");
  EXPECT_EQ(tsah::availableMemoryBytes(), std::size_t(1) << 20);
  EXPECT_EQ(failureOf(std::size_t(2) << 20),
            "who: what would need 2 MiB, more than the 1 MiB of memory available (TSAH_MEMORY_LIMIT_MB)");
  EXPECT_EQ(failureOf(std::size_t(1) << 20), "") << "exactly the budget fits";
}

TEST(MemoryBudget, RenderFrameStatesItsBuffersBeforeAllocating) {
  tsah::RenderSettings settings;
  settings.width = settings.height = 16384;
  EXPECT_GT(tsah::renderFrameBytes(settings, 0), std::size_t(12) << 30) << "~13 GiB at 16384 x 16384";

  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 2);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  tsah::CpuRuntime rt(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), tsah::CpuRuntime::Config(1));
  rt.update(a.keyframe(0));
  const tsah::Aabb bounds = tsah::test::boxOf(a.bounds());
  const tsah::Camera camera = tsah::fitCamera(bounds, {0, 1, 0}, 45.0f, 1.0f);
  const tsah::SceneLighting lighting = tsah::fitLighting(bounds, camera);
  settings.width = settings.height = 1024;  // ~50 MiB of buffers
  tsah::Image image;
  const MemoryLimit small("8");
  EXPECT_THROW(tsah::renderFrame(rt, camera, lighting, settings, image), tsah::Failure);
  EXPECT_TRUE(image.rgb.empty()) << "nothing was allocated";
}

}  // namespace
