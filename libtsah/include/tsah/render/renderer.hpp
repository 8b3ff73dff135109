#pragma once
// The image the runtimes produce for a frame (the paper's Table 2 workload): per pixel one primary
// ray (closest hit), N ambient-occlusion rays (cosine hemisphere, any hit, limited length) and M
// shadow rays towards an area light (any hit). Each ray type is traced in its own pass over the
// image so its rate can be measured alone, as separate GPU kernels would be. An optional ground
// plane (analytic, not in the BVH) receives shadows and occlusion from the animated mesh.
#include <cstddef>
#include <cstdint>

#include "tsah/render/camera.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/shading.hpp"  // SceneLighting and the per-pixel math

namespace tsah {

// Lighting fitted to a box (the animation's bounds over all frames) seen by camera: an area light
// above the scene, in front of and to the side of the camera so shadows fall visibly; AO rays up
// to aoFraction of the box diagonal; the ground just below the box.
SceneLighting fitLighting(const Aabb& bounds, const Camera& camera, Vec3 up = {0, 1, 0}, float aoFraction = 0.1f,
                          bool ground = true);

struct RenderSettings {
  uint32_t width = 1024, height = 768;
  uint32_t aoSamples = 8;
  uint32_t shadowSamples = 2;
  uint32_t frame = 0;  // enters the per-pixel random numbers
  uint32_t seed = 1;
};

struct RayPassStats {
  uint64_t rays = 0;
  double ms = 0.0;
  double mraysPerSecond() const { return ms > 0.0 ? double(rays) / (ms * 1e3) : 0.0; }
};

struct RenderStats {
  RayPassStats primary, ao, shadow;
  double shadeMs = 0.0;  // turning the passes' results into pixels (not ray tracing)
  RayPassStats total() const {
    return {primary.rays + ao.rays + shadow.rays, primary.ms + ao.ms + shadow.ms};
  }
};

// The memory renderFrame allocates for one frame of these settings: per pixel its surface, AO and
// light factors and RGB, and the vertex normals of a mesh of `vertices`. (16384 x 16384: ~13 GiB.)
std::size_t renderFrameBytes(const RenderSettings& settings, uint32_t vertices);

// The surface the primary ray `ray` finds in the runtime's blurred frame at shutter fraction
// `time` (renderFrame's first pass for a blurred runtime): the hit triangle's vertices lerped at
// that time, as the traversal lerps them. The runtime must be blurred().
Surface blurredSurface(const CpuRuntime& runtime, const Ray& ray, float time, const SceneLighting& lighting);

// Renders the runtime's current frame into image (resized to the settings). A blurred runtime
// (CpuRuntime::updateShutter): each pixel's primary, AO and shadow rays share the pixel's time,
// pixelShutterTime (tsah/render/sampling.hpp). Deterministic: the same
// inputs give the same image for any thread count. Throws tsah::ConfigError for an empty image size
// and tsah::Failure when renderFrameBytes does not fit the memory (tsah/base/memory.hpp), before
// allocating any of it.
RenderStats renderFrame(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                        const RenderSettings& settings, Image& image);

}  // namespace tsah
