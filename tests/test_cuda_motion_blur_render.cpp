// Motion-blurred frames rendered on the GPU (renderFrameGpu of a blurred runtime): the image of the
// CPU renderer's blurred frame (same per-pixel times, same hits), fused and separate passes alike;
// a closed shutter renders the instant bit for bit; a shutter whose keys do not move renders the
// instant's image. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <span>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;
using tsah::test::generatedAnimation;

tsah::FlatBvh sahTree(const anim::Animation& a) {
  tsah::LeafCollapser::Config c;
  c.maxLeafSize = 4;
  return tsah::flattenBvh(tsah::LeafCollapser(c).collapse(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0))));
}

tc::GpuRuntime::Config passesConfig(bool fused) {
  tc::GpuRuntime::Config c = tsah::test::gpuConfig(tsah::Layout::Bvh2);
  c.fusePasses = fused;
  return c;
}

tsah::Image renderGpu(tc::GpuRuntime& gpu, const tsah::test::RenderView& view, const tsah::SceneLighting& lighting,
                      tsah::RenderStats* stats = nullptr) {
  tsah::Image image;
  const tsah::RenderStats s = tc::renderFrameGpu(gpu, view.camera, lighting, view.settings, image);
  if (stats) *stats = s;
  return image;
}

// Shutters inside one keyframe interval (two keys) and over several (keyframes inside), fused and
// separate passes: the GPU's blurred image is the CPU renderer's (the same times per pixel, the same
// traversal; only the device's sin/cos/pow/exp may differ in the last bit), the two pass schemes
// give the same image bit for bit, and the blur shows: the image is not the instant's at the
// shutter's middle.
TEST(CudaMotionBlurRender, BlurredImageMatchesTheCpuRenderersBlurredImage) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 4000, 6);
  const tsah::FlatBvh tree = sahTree(a);
  tsah::CpuRuntime cpu(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  tc::GpuRuntime fused(tree, a, passesConfig(true)), separate(tree, a, passesConfig(false));
  tsah::test::RenderView view = tsah::test::renderView(a);
  const tsah::SceneLighting lighting = tsah::fitLighting(view.bounds, view.camera);
  const double t0 = a.startTime(), span = a.endTime() - a.startTime();
  uint32_t frame = 0;
  for (auto [open, close] : {std::pair{t0 + 0.42 * span, t0 + 0.58 * span}, std::pair{t0 + 0.1 * span, t0 + 0.9 * span}}) {
    const std::string what = "shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]";
    view.settings.frame = frame++;
    tsah::updateShutter(cpu, a, open, close);
    fused.updateShutterAt(open, close);
    separate.updateShutterAt(open, close);
    ASSERT_TRUE(cpu.blurred()) << what;
    ASSERT_TRUE(fused.blurred()) << what;
    ASSERT_EQ(fused.shutterKeyCount(), cpu.keyTimes().size()) << what;
    tsah::Image cpuImage;
    const tsah::RenderStats expect = tsah::renderFrame(cpu, view.camera, lighting, view.settings, cpuImage);
    tsah::RenderStats got, gotSeparate;
    const tsah::Image fusedImage = renderGpu(fused, view, lighting, &got);
    const tsah::Image separateImage = renderGpu(separate, view, lighting, &gotSeparate);
    tsah::test::expectRayCountsClose(got, expect);
    EXPECT_GT(got.ao.rays, 0u) << what;
    EXPECT_GT(got.shadow.rays, 0u) << what;
    tsah::test::expectImagesClose(cpuImage, fusedImage, "fused, " + what);
    EXPECT_EQ(got.ao.rays, gotSeparate.ao.rays) << what;
    EXPECT_EQ(got.shadow.rays, gotSeparate.shadow.rays) << what;
    EXPECT_TRUE(fusedImage.rgb == separateImage.rgb) << "fused against separate passes, " << what;

    tc::GpuRuntime instant(tree, a);
    instant.updateAt(0.5 * (open + close));
    EXPECT_GT(tsah::compareImages(fusedImage, renderGpu(instant, view, lighting), 16).fractionAbove, 0.002)
        << "the blurred image is the instant's, " << what;
  }
}

// A closed shutter (open == close) is the instant: the image of updateAt bit for bit, also right
// after a blurred frame.
TEST(CudaMotionBlurRender, ClosedShutterRendersTheInstantBitForBit) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 3000, 5);
  const tsah::FlatBvh tree = sahTree(a);
  const tsah::test::RenderView view = tsah::test::renderView(a);
  const tsah::SceneLighting lighting = tsah::fitLighting(view.bounds, view.camera);
  const double t = a.startTime() + 0.37 * (a.endTime() - a.startTime());
  for (bool fusedPasses : {true, false}) {
    tc::GpuRuntime shutter(tree, a, passesConfig(fusedPasses)), instant(tree, a, passesConfig(fusedPasses));
    shutter.updateShutterAt(a.startTime(), a.endTime());
    ASSERT_TRUE(shutter.blurred());
    renderGpu(shutter, view, lighting);
    shutter.updateShutterAt(t, t);
    ASSERT_FALSE(shutter.blurred());
    instant.updateAt(t);
    EXPECT_TRUE(renderGpu(shutter, view, lighting).rgb == renderGpu(instant, view, lighting).rgb)
        << (fusedPasses ? "fused" : "separate") << " passes";
  }
}

// A shutter whose keys all hold the same positions: every pixel's time sees the geometry of the
// instant at those positions, so the blurred image is the instant's (up to the lerp's rounding and
// the watertight test in place of the Woop test: the render tests' tolerance).
TEST(CudaMotionBlurRender, AShutterThatDoesNotMoveRendersTheInstantImage) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 4000, 5);
  const tsah::FlatBvh tree = sahTree(a);
  const tsah::test::RenderView view = tsah::test::renderView(a);
  const tsah::SceneLighting lighting = tsah::fitLighting(view.bounds, view.camera);
  const std::vector<float> still = a.positionsAt(a.startTime() + 0.6 * (a.endTime() - a.startTime()));
  const std::vector<std::span<const float>> keys(3, std::span<const float>(still));
  for (bool fusedPasses : {true, false}) {
    tc::GpuRuntime blurred(tree, a, passesConfig(fusedPasses)), instant(tree, a, passesConfig(fusedPasses));
    blurred.updateShutter(std::vector<float>{0.0f, 0.3f, 1.0f}, keys);
    ASSERT_TRUE(blurred.blurred());
    instant.update(still);
    tsah::RenderStats got, expect;
    const tsah::Image blurredImage = renderGpu(blurred, view, lighting, &got);
    const tsah::Image instantImage = renderGpu(instant, view, lighting, &expect);
    const std::string what = fusedPasses ? "fused passes" : "separate passes";
    tsah::test::expectRayCountsClose(got, expect);
    EXPECT_GT(got.ao.rays, 0u) << what;
    tsah::test::expectImagesClose(blurredImage, instantImage, what);
  }
}

}  // namespace

#else

TEST(CudaMotionBlurRender, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
