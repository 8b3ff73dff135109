#include "tsah/scene/two_level_render.hpp"

#include <algorithm>
#include <chrono>

#include "anim/scene.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/render/render_loop.hpp"

namespace tsah {

TwoLevelRenderView::TwoLevelRenderView(const TwoLevelRuntime& runtime) : runtime_(runtime) {
  const anim::SceneSources& scene = runtime.scene().scene;
  uint64_t triangles = 0, vertices = 0;
  for (const anim::SceneSourceInstance& instance : scene.instances) {
    firstTriangle_.push_back(static_cast<uint32_t>(triangles));
    firstVertex_.push_back(static_cast<uint32_t>(vertices));
    triangles += scene.sourceOf(instance).triangleCount();
    vertices += scene.sourceOf(instance).vertexCount();
    // Triangle and vertex ids of the world mesh are 32-bit, as in the baked scene.
    if (triangles >= kNoHit || vertices >= kNoHit)
      throw DataError(scene.description.file + ": more than 2^32 triangles or vertices in the world mesh to shade");
  }
  indices_.reserve(std::size_t(triangles) * 3);
  for (std::size_t i = 0; i < scene.instances.size(); ++i)
    for (uint32_t v : scene.sourceOf(scene.instances[i]).indices()) indices_.push_back(firstVertex_[i] + v);
  positions_.resize(std::size_t(vertices) * 3);
  updateMesh();
}

double TwoLevelRenderView::updateMesh() {
  const auto start = std::chrono::steady_clock::now();
  const anim::SceneSources& scene = runtime_.scene().scene;
  const double t = runtime_.time();
  runtime_.parallelFor(scene.instances.size(), 1, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) {
      const anim::SceneSourceInstance& instance = scene.instances[i];
      const anim::Animation& source = scene.sourceOf(instance);
      float* out = positions_.data() + std::size_t(firstVertex_[i]) * 3;
      source.positionsAt(instance.localTime(t, source), std::span<float>(out, std::size_t(source.vertexCount()) * 3));
      anim::transformPoints(instance.worldAt(t), out, source.vertexCount());
    }
  });
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

Hit TwoLevelRenderView::closestHit(const Ray& ray) const {
  const TwoLevelHit hit = runtime_.closestHit(ray);
  if (!hit.valid()) return {};
  return {hit.t, hit.u, hit.v, firstTriangle_[hit.instance] + hit.prim};
}

bool TwoLevelRenderView::anyHit(const Ray& ray, AnyHitOrder order) const { return runtime_.anyHit(ray, order); }

Hit TwoLevelRenderView::closestHit(const Ray& ray, float time) const {
  const TwoLevelHit hit = runtime_.closestHit(ray, time);
  if (!hit.valid()) return {};
  return {hit.t, hit.u, hit.v, firstTriangle_[hit.instance] + hit.prim};
}

bool TwoLevelRenderView::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  return runtime_.anyHit(ray, time, order);
}

Surface TwoLevelRenderView::blurredSurface(const Ray& ray, const Hit& hit, float time, const SceneLighting& lighting) const {
  if (!hit.valid()) return primarySurface(ray, hit, nullptr, nullptr, lighting);
  const uint32_t instance = uint32_t(std::upper_bound(firstTriangle_.begin(), firstTriangle_.end(), hit.tri) - firstTriangle_.begin()) - 1;
  const uint32_t prim = hit.tri - firstTriangle_[instance];
  const CpuRuntime& blas = runtime_.blasOf(instance);
  const Affine3x4 toWorld = runtime_.toWorldAt(instance, time);
  // The BLAS's vertices at the time: its key positions lerped when it is blurred, else its positions.
  const float* p0 = blas.positions().data();
  const float* p1 = p0;
  float f = 0.0f;
  if (blas.blurred()) {
    const MotionBvhView& view = blas.motionView();
    const motion::Segment seg = motion::segmentAt(view.keyTimes, int(view.keyCount), time);
    p0 = view.keyPositions + std::size_t(seg.index) * view.vertexCount * 3;
    p1 = p0 + std::size_t(view.vertexCount) * 3;
    f = seg.f;
  }
  float triangle[9];
  for (int k = 0; k < 3; ++k) {
    const uint32_t vertex = blas.indices()[3 * std::size_t(prim) + k];
    const Vec3 v = toWorld.point(motion::lerpVertex(loadVec3(p0, vertex), loadVec3(p1, vertex), f));
    triangle[3 * k] = v.x;
    triangle[3 * k + 1] = v.y;
    triangle[3 * k + 2] = v.z;
  }
  return primarySurfaceOnTriangle(ray, hit, triangle, lighting);
}

RenderStats renderFrame(const TwoLevelRenderView& view, const Camera& camera, const SceneLighting& lighting,
                        const RenderSettings& settings, Image& image) {
  return renderFrameOf(view, camera, lighting, settings, image);
}

}  // namespace tsah
