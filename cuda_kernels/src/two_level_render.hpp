#pragma once
// The two-level renderer's device side (two_level_render.cu), called by GpuTwoLevelRenderer
// (gpu_two_level_render.cpp); no CUDA syntax here, so the C++ compiler reads it too.
#include <cuda_runtime_api.h>

#include <cstdint>

#include "render_passes.cuh"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/shading.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

// What the tracer and the shading read: the frame's trace scene and, per instance, its first
// triangle in bake order and where its source's vertex -> triangle lists start (device pointers).
struct TwoLevelShadingTables {
  TlasScene scene;
  const uint32_t* firstTriangle = nullptr;     // instanceCount + 1 entries, ascending
  uint32_t instanceCount = 0;
  const uint32_t* sourceOffsets = nullptr;     // per instance: its source's first entry in vertexTriOffsets
  const uint32_t* vertexTriOffsets = nullptr;  // per source vertexCount + 1 entries, into vertexTris
  const uint32_t* vertexTris = nullptr;        // per source vertex: its triangles, increasing
};

// One frame: the fused passes (the shadow pass on b.side), the shading and the download of the
// image (when not null), on b.stream; waits for it and returns its stats (b from
// PassBufferSet::startFrame: the counters zeroed and event 0 recorded). blurred (not null: a blurred
// frame, tables.scene its instant state at the close): every ray of a pixel traced at the pixel's
// shutter time and the primary surface on the hit triangle where it is then, as the CPU renderer
// renders a blurred two-level frame (TwoLevelRenderView::blurredSurface); the smooth normals of the
// shading are the close's.
RenderStats renderTwoLevelFrame(const PassBuffers& b, const Frame& f, const TwoLevelShadingTables& tables,
                                const BlurredTlasScene* blurred, uint64_t aoRays, uint64_t shadowRays, Image* image,
                                GpuRenderTimings* timings);

// The fused passes' surfaces (3 float4 per padded pixel) as one Surface per pixel, row-major.
void launchUnpackSurfaces(const Frame& f, const float4* surfaces, Surface* out, cudaStream_t stream);

}  // namespace tsah::cuda::detail
