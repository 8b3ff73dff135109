// Two-level frames rendered on the GPU (GpuTwoLevelRenderer over a GpuTwoLevelRuntime) against the
// CPU renderer's frames of the same scene (TwoLevelRuntime in bvh2 + TwoLevelRenderView): the same
// primary surface at every pixel (kind, triangle in bake order, position, normal) and the same
// image, at scene times between frames and at frames, with rotations, non-uniform scales, mirrored
// placements, paths, time offsets and a looping pose; blurred frames; an instance flattened by its
// path is not rendered, and rendered mirrored afterwards; a TLAS rebuilt every frame renders the same
// frames.
// Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cmath>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/render/shading.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_render.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "tsah_cuda/gpu_two_level_render.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace {

namespace fs = std::filesystem;

// Both renderers trace the same rays with the same traversal and surface math; the device compiles
// its transforms without fused multiply-adds as the CPU does, but a compiler may still round the
// ray's move into instance space differently: positions and normals agree within a relative 1e-4.
constexpr float kRelative = 1e-4f;
// A pixel may name another triangle on a tie: two triangles at the same distance along its ray
// (a ray through a shared edge or vertex, coincident surfaces); the GPU's loop visits them in its
// own order and keeps the first it accepts. At most 1% of the mesh pixels may differ so.
constexpr double kTieFraction = 0.01;

bool near(float a, float b) { return std::fabs(a - b) <= kRelative * (1.0f + std::fabs(a)); }
bool near(const tsah::Vec3& a, const tsah::Vec3& b) { return near(a.x, b.x) && near(a.y, b.y) && near(a.z, b.z); }

struct Frame {
  tsah::Camera camera;
  tsah::SceneLighting lighting;
  tsah::RenderSettings settings;
};

// A camera above and in front of the instances' boxes at the CPU runtime's time (the cloth and the
// ground are sheets: seen from above they cover 1,500 to 1,700 pixels of the frame, every instance
// in view, on the CPU renderer).
Frame frameFor(const tsah::TwoLevelRuntime& cpu, uint32_t index) {
  tsah::Aabb bounds;
  for (const tsah::Aabb& b : cpu.instanceBoxes()) bounds.extend(b);
  Frame f;
  f.settings.width = 160;
  f.settings.height = 120;
  f.settings.aoSamples = 4;
  f.settings.shadowSamples = 2;
  f.settings.frame = index;
  const tsah::Vec3 center = (bounds.lo + bounds.hi) * 0.5f, extent = bounds.hi - bounds.lo;
  const float radius = 0.5f * std::sqrt(tsah::dot(extent, extent));
  f.camera = {center + tsah::normalize(tsah::Vec3{0.4f, 1.0f, 0.7f}) * (2.4f * radius), center, {0, 1, 0}, 45.0f};
  f.lighting = tsah::fitLighting(bounds, f.camera);
  return f;
}

// The CPU renderer's primary surfaces (renderFrameOf's pass 1), row-major; of a blurred frame at
// each pixel's shutter time.
std::vector<tsah::Surface> cpuSurfaces(const tsah::TwoLevelRuntime& cpu, const tsah::TwoLevelRenderView& view,
                                       const Frame& f) {
  const tsah::CameraRays cam = tsah::cameraRays(f.camera, f.settings.width, f.settings.height);
  std::vector<tsah::Surface> out;
  for (uint32_t y = 0; y < f.settings.height; ++y)
    for (uint32_t x = 0; x < f.settings.width; ++x) {
      const tsah::Ray ray = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
      if (cpu.blurred()) {
        const float time = tsah::pixelShutterTime({f.settings.seed, f.settings.frame, y * f.settings.width + x});
        out.push_back(view.blurredSurface(ray, view.closestHit(ray, time), time, f.lighting));
      } else {
        out.push_back(tsah::primarySurface(ray, view.closestHit(ray), view.indices().data(), view.positions().data(),
                                           f.lighting));
      }
    }
  return out;
}

// Renders the runtimes' current frames (updated alike) on both devices and compares them; returns
// the bake-order triangles of the mesh pixels (on the CPU).
std::set<uint32_t> expectSameRender(const tsah::TwoLevelRuntime& cpu, const tsah::TwoLevelRenderView& view,
                                    tsah::cuda::GpuTwoLevelRenderer& renderer, uint32_t index, const std::string& what) {
  const Frame f = frameFor(cpu, index);
  tsah::Image cpuImage, gpuImage;
  const tsah::RenderStats expect = tsah::renderFrame(view, f.camera, f.lighting, f.settings, cpuImage);
  const tsah::RenderStats got = renderer.render(f.camera, f.lighting, f.settings, &gpuImage);
  const std::vector<tsah::Surface> want = cpuSurfaces(cpu, view, f), have = renderer.downloadSurfaces();
  EXPECT_EQ(have.size(), want.size()) << what;
  if (have.size() != want.size()) return {};
  std::set<uint32_t> triangles;
  std::size_t ties = 0, mesh = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    const tsah::Surface &a = want[i], &b = have[i];
    if (a.kind == tsah::SurfaceKind::Mesh) {
      triangles.insert(a.tri);
      ++mesh;
    }
    if (a.kind != b.kind || (a.kind == tsah::SurfaceKind::Mesh && a.tri != b.tri)) {
      ++ties;
      continue;
    }
    if (a.kind == tsah::SurfaceKind::None) continue;
    EXPECT_TRUE(near(a.position, b.position) && near(a.normal, b.normal) && near(a.u, b.u) && near(a.v, b.v))
        << what << ", pixel " << i << ": position " << a.position.x << " " << a.position.y << " " << a.position.z
        << " against " << b.position.x << " " << b.position.y << " " << b.position.z;
  }
  EXPECT_LE(double(ties), kTieFraction * double(mesh)) << what << ": pixels naming another surface, of " << mesh
                                                      << " mesh pixels";
  tsah::test::expectRayCountsClose(got, expect);
  tsah::test::expectImagesClose(cpuImage, gpuImage, what);
  return triangles;
}

// The instant frame at scene time t on both devices, rendered and compared (expectSameRender).
std::set<uint32_t> expectSameFrame(tsah::TwoLevelRuntime& cpu, tsah::TwoLevelRenderView& view,
                                   tsah::cuda::GpuTwoLevelRuntime& gpu, tsah::cuda::GpuTwoLevelRenderer& renderer,
                                   double t, uint32_t index) {
  cpu.update(t);
  view.updateMesh();
  gpu.updateAt(t);
  return expectSameRender(cpu, view, renderer, index, "scene time " + std::to_string(t));
}

// The instance of each bake-order triangle.
std::vector<uint32_t> instanceOfTriangle(const tsah::TwoLevelScene& scene) {
  std::vector<uint32_t> out;
  for (uint32_t i = 0; i < scene.instanceCount(); ++i)
    out.insert(out.end(), scene.scene.sourceOf(scene.scene.instances[i]).triangleCount(), i);
  return out;
}

class CudaTwoLevelRender : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_GPU();
    dir = tsah::test::scratchDir();
  }
  tsah::TwoLevelScene load(const fs::path& scene) {
    return tsah::loadTwoLevelScene(scene.string(), {}, tsah::test::smallTwoLevelOptions());
  }
  fs::path dir;
};

// The GPU runtime's configuration with its BLAS in `layout`.
tsah::cuda::GpuTwoLevelRuntime::Config blasIn(tsah::Layout layout) {
  tsah::cuda::GpuTwoLevelRuntime::Config config;
  config.layout = layout;
  return config;
}

// Between frames and at frames, poses moving, paths moving, the loop wrapped: the GPU's frame is
// the CPU renderer's, and every instance is seen, with the BLAS in either GPU layout.
TEST_F(CudaTwoLevelRender, SurfacesAndImageEqualTheCpuRenderersFrames) {
  const tsah::TwoLevelScene scene = load(tsah::test::writeTwoLevelScene(dir));
  tsah::TwoLevelRuntime cpu(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::TwoLevelRenderView view(cpu);
  for (const tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Cwbvh}) {
    SCOPED_TRACE(tsah::name(layout));
    tsah::cuda::GpuTwoLevelRuntime gpu(scene, blasIn(layout));
    tsah::cuda::GpuTwoLevelRenderer renderer(gpu);
    EXPECT_THROW(renderer.downloadSurfaces(), tsah::ConfigError);
    const std::vector<uint32_t> instanceOf = instanceOfTriangle(scene);
    std::set<uint32_t> seen;
    uint32_t index = 0;
    for (const double t : {0.0, 3.25, 7.5, 12.0}) {
      const std::set<uint32_t> triangles = expectSameFrame(cpu, view, gpu, renderer, t, index++);
      EXPECT_GT(triangles.size(), 500u) << "scene time " << t << ": too few triangles in view";
      for (uint32_t tri : triangles) seen.insert(instanceOf.at(tri));
    }
    EXPECT_EQ(seen.size(), scene.instanceCount()) << "instances seen in the frames";
  }
}

// A runtime that rebuilds its TLAS every frame (LBVH, HLBVH-SAH: the T-SAH TLAS never uploaded)
// renders the CPU renderer's frames too: the renderer traces the frame's rebuilt tree.
TEST_F(CudaTwoLevelRender, ARebuiltTlasRendersTheCpuRenderersFrames) {
  const tsah::TwoLevelScene scene = load(tsah::test::writeTwoLevelScene(dir));
  tsah::TwoLevelRuntime cpu(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::TwoLevelRenderView view(cpu);
  for (const auto update : {tsah::cuda::TlasUpdate::Lbvh, tsah::cuda::TlasUpdate::HlbvhSah}) {
    SCOPED_TRACE(tsah::cuda::tlasUpdateName(update));
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.tlas = update;
    tsah::cuda::GpuTwoLevelRuntime gpu(scene, config);
    tsah::cuda::GpuTwoLevelRenderer renderer(gpu);
    uint32_t index = 0;
    for (const double t : {0.0, 7.5, 12.0})
      EXPECT_GT(expectSameFrame(cpu, view, gpu, renderer, t, index++).size(), 500u) << "scene time " << t;
  }
}

// Blurred frames (shutters of 2 and 3 keys, one after two poses' clip ends, one over the whole
// scene): every ray at its pixel's time, the primary surface on the hit triangle where it is then;
// the GPU's surfaces and image are the CPU renderer's, and differ from the close's instant frame;
// with the BLAS in either GPU layout.
TEST_F(CudaTwoLevelRender, BlurredFramesEqualTheCpuRenderersFrames) {
  const tsah::TwoLevelScene scene = load(tsah::test::writeTwoLevelScene(dir));
  tsah::TwoLevelRuntime cpu(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::TwoLevelRenderView view(cpu);
  for (const tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Cwbvh}) {
    SCOPED_TRACE(tsah::name(layout));
    tsah::cuda::GpuTwoLevelRuntime gpu(scene, blasIn(layout));
    tsah::cuda::GpuTwoLevelRenderer renderer(gpu);
    uint32_t index = 0;
    for (const auto& [open, close] : {std::pair{2.1, 2.4}, std::pair{6.2, 6.9}, std::pair{9.2, 9.9}, std::pair{0.0, 12.0}}) {
      const std::string what = "shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]";
      cpu.updateShutter(open, close);
      view.updateMesh();
      gpu.updateShutter(open, close);
      ASSERT_TRUE(cpu.blurred() && gpu.blurred()) << what;
      const std::set<uint32_t> triangles = expectSameRender(cpu, view, renderer, index, what);
      EXPECT_GT(triangles.size(), 500u) << what << ": too few triangles in view";
      // The instant frame at the close renders otherwise (the blur is seen).
      const Frame f = frameFor(cpu, index++);
      const std::vector<tsah::Surface> blurred = renderer.downloadSurfaces();
      gpu.updateAt(close);
      renderer.render(f.camera, f.lighting, f.settings, nullptr);
      const std::vector<tsah::Surface> instant = renderer.downloadSurfaces();
      std::size_t moved = 0;
      for (std::size_t i = 0; i < blurred.size(); ++i)
        moved += blurred[i].kind != instant[i].kind || !near(blurred[i].position, instant[i].position) ? 1 : 0;
      EXPECT_GT(moved, 50u) << what << ": blurred pixels";
    }
  }
}

// An instance flattened by its path (t = 1: singular world matrix) renders no mesh pixel; before
// and after (mirrored) the GPU's frames are the CPU's.
TEST_F(CudaTwoLevelRender, AFlattenedInstanceIsNotRenderedAndItsMirrorIs) {
  const tsah::TwoLevelScene scene = load(tsah::test::writeFlattenedTriangleScene(dir));
  tsah::TwoLevelRuntime cpu(scene, {1, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::TwoLevelRenderView view(cpu);
  tsah::cuda::GpuTwoLevelRuntime gpu(scene);
  tsah::cuda::GpuTwoLevelRenderer renderer(gpu);
  EXPECT_EQ(expectSameFrame(cpu, view, gpu, renderer, 0.0, 0).size(), 1u);
  EXPECT_EQ(expectSameFrame(cpu, view, gpu, renderer, 2.0, 2).size(), 1u);
  // At t = 1, seen by the camera of t = 0, nothing of it is rendered.
  cpu.update(0.0);
  const Frame f = frameFor(cpu, 1);
  gpu.updateAt(1.0);
  renderer.render(f.camera, f.lighting, f.settings, nullptr);
  for (const tsah::Surface& s : renderer.downloadSurfaces()) ASSERT_NE(s.kind, tsah::SurfaceKind::Mesh);
}

}  // namespace

#else

TEST(CudaTwoLevelRender, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
