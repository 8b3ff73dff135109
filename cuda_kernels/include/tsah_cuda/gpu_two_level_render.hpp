#pragma once
// tsah::renderFrame of a two-level scene on the device (docs/two-level.md): the GPU renderer's fused
// passes (primary closest hit, ambient occlusion, shadows; the same camera rays, random numbers and
// shading as the CPU renderer) traced through a GpuTwoLevelRuntime's current frame: the TLAS, and
// at its leaves each instance's BLAS with the ray in instance space. Rays are made and consumed on
// the device.
//
// The surface at a hit is the CPU renderer's (tsah::TwoLevelRenderView) bit for bit: the hit
// triangle's pose positions moved into the world by the instance's world(t) in double and rounded
// to float, as the baked scene's vertices are (anim::transformPoints), then tsah::primarySurface on
// that triangle (the geometric normal is the cross product of its world-space edges). The smooth
// shading normal sums, per vertex of the hit triangle, the world-space face normals of the
// vertex's triangles in the instance, in increasing triangle order, as the CPU renderer's world mesh
// does. Surfaces name the triangle in bake order (the triangles of instance i after those of
// instances 0..i-1), as the CPU renderer's do. A blurred frame (GpuTwoLevelRuntime::updateShutter)
// is rendered as the CPU renderer renders one: every ray at its pixel's shutter time, the primary
// surface on the hit triangle at that time (the pose's key positions lerped, moved by the lerped key
// matrices), the smooth normals of the close.
#include <memory>
#include <vector>

#include "tsah/render/camera.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/shading.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"

namespace tsah::cuda {

class GpuTwoLevelRenderer {
 public:
  // Keeps a reference to `runtime` (it must outlive the renderer); uploads the shading tables (per
  // instance its first triangle in bake order, per source the triangles of each vertex). Call with
  // the runtime's device current. Throws tsah::DataError when the world mesh has 2^32 triangles or
  // more (triangle ids are 32-bit, as in the baked scene).
  explicit GpuTwoLevelRenderer(GpuTwoLevelRuntime& runtime);
  ~GpuTwoLevelRenderer();
  GpuTwoLevelRenderer(const GpuTwoLevelRenderer&) = delete;
  GpuTwoLevelRenderer& operator=(const GpuTwoLevelRenderer&) = delete;

  // One frame of the runtime's current state (its last updateAt). image == nullptr skips the
  // download. Throws tsah::ConfigError for an empty image size or an invalid camera, as the CPU
  // renderer does.
  RenderStats render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings, Image* image,
                     GpuRenderTimings* timings = nullptr);

  // The primary surfaces of the last render, one per pixel, row-major: kind, position, normal and
  // for mesh hits the triangle in bake order and u, v (other fields of pixels without a mesh hit
  // as a default Surface's, except the ground's position and normal).
  std::vector<Surface> downloadSurfaces() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace tsah::cuda
