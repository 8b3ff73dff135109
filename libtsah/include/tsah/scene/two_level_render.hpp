#pragma once
// Rendering a two-level scene with the renderer's workload (tsah/render/renderer.hpp): the render
// loop (tsah/render/render_loop.hpp) traces through a TwoLevelRuntime and shades from the scene's
// world mesh at the runtime's time, the instances' triangles in bake order (the triangles of
// instance i after those of instances 0..i-1, as anim::bakeScene lays them out), so a two-level
// frame and the flat baked scene's frame shade the same triangles the same way. A blurred runtime
// renders blurred frames: every ray of a pixel at the pixel's shutter time (the render loop's).
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "tsah/layout/wide_traversal.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/shading.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah {

class TwoLevelRenderView {
 public:
  // Keeps a reference to `runtime` (and its scene); they must outlive the view.
  explicit TwoLevelRenderView(const TwoLevelRuntime& runtime);

  // The world mesh at the runtime's current time (call after TwoLevelRuntime::update, or
  // updateShutter: its close, whose positions the smooth normals of a blurred frame read): every
  // instance's source positions at its local time moved by its world matrix (anim::transformPoints,
  // as the bake moves them). Returns the milliseconds it took.
  double updateMesh();

  // Hits with tri = the first triangle of the hit instance (in bake order) + the triangle in its source.
  Hit closestHit(const Ray& ray) const;
  bool anyHit(const Ray& ray, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;
  // A blurred frame (TwoLevelRuntime::updateShutter): traced at each ray's shutter fraction, and the
  // surface of a primary hit at `time` on its triangle where the frame has it then (the BLAS's
  // vertices lerped at the time, moved by the instance's lerped map, toWorldAt).
  bool blurred() const { return runtime_.blurred(); }
  Hit closestHit(const Ray& ray, float time) const;
  bool anyHit(const Ray& ray, float time, AnyHitOrder order) const;
  Surface blurredSurface(const Ray& ray, const Hit& hit, float time, const SceneLighting& lighting) const;
  void parallelFor(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) const {
    runtime_.parallelFor(n, grain, body);
  }
  std::span<const uint32_t> indices() const { return indices_; }
  std::span<const float> positions() const { return positions_; }
  uint32_t triangleCount() const { return static_cast<uint32_t>(indices_.size() / 3); }
  uint32_t vertexCount() const { return static_cast<uint32_t>(positions_.size() / 3); }

 private:
  const TwoLevelRuntime& runtime_;
  std::vector<uint32_t> firstTriangle_;  // per instance
  std::vector<uint32_t> firstVertex_;    // per instance
  std::vector<uint32_t> indices_;
  std::vector<float> positions_;
};

// renderFrame (tsah/render/renderer.hpp) of a two-level scene at the view's current mesh.
RenderStats renderFrame(const TwoLevelRenderView& view, const Camera& camera, const SceneLighting& lighting,
                        const RenderSettings& settings, Image& image);

}  // namespace tsah
