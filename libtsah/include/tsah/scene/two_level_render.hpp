#pragma once
// Rendering a two-level scene with the renderer's workload (tsah/render/renderer.hpp): the render
// loop (tsah/render/render_loop.hpp) traces through a TwoLevelRuntime and shades from the scene's
// world mesh at the runtime's time, the instances' triangles in bake order (the triangles of
// instance i after those of instances 0..i-1, as anim::bakeScene lays them out), so a two-level
// frame and the flat baked scene's frame shade the same triangles the same way.
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "tsah/layout/wide_traversal.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah {

class TwoLevelRenderView {
 public:
  // Keeps a reference to `runtime` (and its scene); they must outlive the view.
  explicit TwoLevelRenderView(const TwoLevelRuntime& runtime);

  // The world mesh at the runtime's current time (call after TwoLevelRuntime::update): every
  // instance's source positions at its local time moved by its world matrix (anim::transformPoints,
  // as the bake moves them). Returns the milliseconds it took.
  double updateMesh();

  // Hits with tri = the first triangle of the hit instance (in bake order) + the triangle in its source.
  Hit closestHit(const Ray& ray) const;
  bool anyHit(const Ray& ray, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;
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
