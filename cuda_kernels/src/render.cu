// tsah::renderFrame on the GPU: the same three ray passes (primary closest hit, ambient occlusion,
// shadows), fused (render_passes.cuh, shared with the two-level renderer) or one kernel per step.
// The per-pixel math (camera rays, the primary surface, the AO and shadow rays, vertex normals,
// shading) is libtsah's shading.hpp, which the CPU renderer uses too.
//
// A blurred frame (GpuRuntime::updateShutter) is rendered as the CPU renderer renders one: every
// ray of a pixel at the pixel's shutter time (pixelShutterTime), traced by the binary traversal
// over the keys of its segment in the blurred layout (bvh2BlurredClosestHit / AnyHit, as the
// blurred batch queries, blurred_traversal.cu), the primary surface on the hit triangle lerped at that time
// (blurredPrimarySurface).
//
// Compiled with -fmad=false, so that math rounds exactly as on the CPU (see shading.hpp); only
// cosf/sinf/powf/expf (the sample warps and the sRGB curve) can differ from the C library in the
// last bit.
#include <cuda/atomic>

#include "tsah/base/error.hpp"
#include "blurred_trace.hpp"
#include "bvh2_traversal.cuh"
#include "cwbvh_kernels.hpp"
#include "kernels.hpp"
#include "launch.hpp"
#include "render_passes.cuh"
#include "runtime_impl.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/shading.hpp"

namespace tsah::cuda {

namespace {

using namespace detail;  // the shared passes (render_passes.cuh)

// A blurred frame: its first part's keys (keyCount >= 2); an instant frame has keyCount 0.
__device__ __forceinline__ bool isBlurred(const BlurredShutter& shutter) { return shutter.first.view.keyCount >= 2; }

__device__ __forceinline__ Ray noRay() {
  Ray r;
  r.org = {0.0f, 0.0f, 0.0f};
  r.dir = {0.0f, 0.0f, 1.0f};
  r.tmin = 0.0f;
  r.tmax = -1.0f;  // an empty interval: misses every box
  return r;
}

__device__ __forceinline__ void storeRay(Ray* rays, std::size_t i, const Ray& r) {
  float4* p = reinterpret_cast<float4*>(rays + i);
  p[0] = make_float4(r.org.x, r.org.y, r.org.z, r.tmin);
  p[1] = make_float4(r.dir.x, r.dir.y, r.dir.z, r.tmax);
}

// times (a blurred frame, else null): each ray's shutter time, its pixel's.
__global__ void primaryRaysKernel(Frame f, Ray* __restrict__ rays, float* __restrict__ times) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  storeRay(rays, j, pixelOf(f, j, x, y) ? cameraRay(f, x, y) : noRay());
  if (times) times[j] = pixelShutterTime(pixelKey(f, j));
}

// The primary pass's surface: mesh hit or the analytic ground, offset along the normal. A blurred
// frame (shutter): the hit triangle at the pixel's time, in the part of that time.
__global__ void surfaceKernel(Frame f, const Hit* __restrict__ hits, const uint32_t* __restrict__ indices,
                              const float* __restrict__ positions, BlurredShutter shutter, float4* __restrict__ surfaces) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  Surface s;
  if (pixelOf(f, j, x, y)) {
    if (isBlurred(shutter)) {
      const float time = pixelShutterTime(pixelKey(f, j));
      s = blurredPrimarySurface(cameraRay(f, x, y), hits[j], viewAt(shutter, time), time, f.light);
    } else {
      s = primarySurface(cameraRay(f, x, y), hits[j], indices, positions, f.light);
    }
  }
  storeSurface(surfaces, j, s);
}

// Secondary ray r of a pass with `samples` rays per padded pixel: its pixel's surface, random-number
// key and sample index; valid when the pixel is in the image and its primary ray found a surface.
struct SecondarySample {
  Surface surface;
  SampleKey key;
  uint32_t sample;
  bool valid;
};

__device__ __forceinline__ SecondarySample secondarySample(const Frame& f, const float4* surfaces, uint64_t r,
                                                           uint32_t samples) {
  const uint32_t j = uint32_t(r / samples);
  uint32_t x, y;
  const bool inside = pixelOf(f, j, x, y);
  SecondarySample out{loadSurface(surfaces, j), f.base, uint32_t(r % samples), false};
  out.key.pixel = pixelIndex(f, x, y);
  out.valid = inside && out.surface.kind != SurfaceKind::None;
  return out;
}

__global__ void aoRaysKernel(Frame f, const float4* __restrict__ surfaces, Ray* __restrict__ rays,
                             float* __restrict__ times, uint32_t* __restrict__ words) {
  const uint64_t r = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= uint64_t(f.padded) * f.aoSamples) return;
  const SecondarySample p = secondarySample(f, surfaces, r, f.aoSamples);
  storeRay(rays, r, p.valid ? aoRay(p.surface, p.key, p.sample, f.light.aoDistance) : noRay());
  if (times) times[r] = pixelShutterTime(p.key);
  countRays(words + kAoRays, p.valid);
}

__global__ void shadowRaysKernel(Frame f, const float4* __restrict__ surfaces, Ray* __restrict__ rays,
                                 float* __restrict__ times, uint8_t* __restrict__ traced, uint32_t* __restrict__ words) {
  const uint64_t r = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= uint64_t(f.padded) * f.shadowSamples) return;
  const SecondarySample p = secondarySample(f, surfaces, r, f.shadowSamples);
  Ray ray;
  // A light point behind the surface: no ray, not lit.
  const bool valid = p.valid && shadowRay(p.surface, f.light, p.key, p.sample, ray);
  storeRay(rays, r, valid ? ray : noRay());
  if (times) times[r] = pixelShutterTime(p.key);
  traced[r] = valid ? 1 : 0;
  countRays(words + kShadowRays, valid);
}

// The fused passes' tracers (render_passes.cuh): the layout's per-ray traversal (bvh2ClosestHit /
// bvh2AnyHit, or the TSAH_HD cwbvhClosestHit / cwbvhAnyHit); same rays, same results as the
// separate kernels above. Every tracer takes each ray's shutter time; kTimed: whether it reads it
// (the instant tracers do not, and the kernels then compute no time).
struct Bvh2Tracer {
  static constexpr bool kTimed = false, kOwnSurface = false;
  detail::TraceScene scene;
  __device__ __forceinline__ Hit closestHit(const Ray& ray, float) const {
    return detail::bvh2ClosestHit(scene, *scene.root, ray);
  }
  __device__ __forceinline__ bool anyHit(const Ray& ray, float) const {
    return detail::bvh2AnyHit(scene, *scene.root, ray);
  }
};

struct CwbvhTracer {
  static constexpr bool kTimed = false, kOwnSurface = false;
  CwbvhView view;  // rootBox is read from root, which the refit writes on the device
  const RootInfo* root;
  __device__ __forceinline__ CwbvhView withRootBox() const {
    CwbvhView v = view;
    v.rootBox = root->box;
    return v;
  }
  __device__ __forceinline__ Hit closestHit(const Ray& ray, float) const { return cwbvhClosestHit(withRootBox(), ray); }
  __device__ __forceinline__ bool anyHit(const Ray& ray, float) const { return cwbvhAnyHit(withRootBox(), ray); }
};

// A blurred frame: the traversal of the blurred batch queries at the ray's time, in its part.
// The surface of a primary hit lerps the hit triangle through the part's key arrays. Parts: the
// frame has later parts (a tree set's shutter across a switch); a frame of one part compiles to the
// one layout's loop without the part lookup (which cost its trace about 1%).
template <bool Parts>
struct BlurredTracer {
  static constexpr bool kTimed = true, kOwnSurface = true;
  detail::BlurredShutter shutter;
  __device__ __forceinline__ Surface surface(const Ray& ray, float time, const SceneLighting& light) const {
    const MotionBvhView view = Parts ? viewAt(shutter, time) : shutter.first.view;
    return blurredPrimarySurface(ray, closestHit(ray, time), view, time, light);
  }
  __device__ __forceinline__ Hit closestHit(const Ray& ray, float time) const {
    if constexpr (Parts) return detail::bvh2BlurredClosestHit(shutter, ray, time);
    return detail::bvh2BlurredClosestHit(shutter.first.layout, ray, time);
  }
  __device__ __forceinline__ bool anyHit(const Ray& ray, float time) const {
    if constexpr (Parts) return detail::bvh2BlurredAnyHit(shutter, ray, time);
    return detail::bvh2BlurredAnyHit(shutter.first.layout, ray, time);
  }
};

// Vertex normals for shading: each vertex sums the face normals of its triangles in increasing
// triangle order, as the CPU loop does, so the sums are bit-identical. vertexTris: the triangles of
// each vertex (CSR).
__global__ void vertexNormalsKernel(uint32_t vertices, const uint32_t* __restrict__ offsets,
                                    const uint32_t* __restrict__ vertexTris, const uint32_t* __restrict__ indices,
                                    const float* __restrict__ positions, float* __restrict__ normals) {
  const uint32_t vtx = blockIdx.x * blockDim.x + threadIdx.x;
  if (vtx >= vertices) return;
  Vec3 n{0, 0, 0};
  for (uint32_t k = offsets[vtx]; k < offsets[vtx + 1]; ++k) n = n + faceNormal(indices, positions, vertexTris[k]);
  normals[3 * std::size_t(vtx)] = n.x;
  normals[3 * std::size_t(vtx) + 1] = n.y;
  normals[3 * std::size_t(vtx) + 2] = n.z;
}

// The flat frame's shading: the smooth normal from the frame's vertex normals.
struct FlatShading {
  const uint32_t* indices;
  const float* normals;
  __device__ __forceinline__ Vec3 color(const Surface& s, const Ray& cameraRay, float ao, float visibility,
                                        const SceneLighting& light) const {
    return pixelColor(s, cameraRay, ao, visibility, indices, normals, light);
  }
};

// Vertex normals of the current positions on stream s (the triangles of each vertex are listed at
// the first call).
void enqueueVertexNormals(GpuRuntime::Impl& m, cudaStream_t s) {
  if (m.vertexTris.empty()) m.buildVertexTriangles();
  const unsigned block = 256;
  vertexNormalsKernel<<<detail::gridFor(m.vertices, block), block, 0, s>>>(
      m.vertices, m.vertexTriOffsets.data(), m.vertexTris.data(), m.indices.data(), m.positions.data(),
      m.normals.data());
  CUDA_CHECK_LAUNCH("vertexNormalsKernel");
}

}  // namespace

RenderStats renderFrameGpu(GpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                           const RenderSettings& settings, Image* image, GpuRenderTimings* timings) {
  uint64_t aoRays = 0, shadowRays = 0;
  const Frame f = makeFrame(camera, lighting, settings, aoRays, shadowRays);
  const uint64_t padded = f.padded;
  GpuRuntime::Impl& m = *runtime.impl_;
  m.requireTraceable();

  // Fused passes (Config::fusePasses) need no ray or hit buffers.
  const detail::TraceScene scene = m.scene();
  const bool fused = m.config.fusePasses;
  // A blurred frame traces its key arrays (keyCount 0: the instant frame).
  const bool blurred = runtime.blurred();
  const detail::BlurredShutter blur = blurred ? m.blurredShutter() : detail::BlurredShutter{};
  float* times = nullptr;  // separate passes of a blurred frame: each ray's shutter time
  if (blurred && !fused) {
    m.rayTimes.reserve(std::max({padded, aoRays, shadowRays}));
    times = m.rayTimes.data();
  }
  // The separate passes' trace: the instant frame's kernel, or the blurred traversal at each ray's time.
  auto trace = [&](const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded, uint32_t* counter) {
    if (blurred)
      detail::launchBlurredTrace(blur, rays, times, count, hits, occluded, m.stream);
    else
      detail::launchTrace(scene, rays, count, hits, occluded, counter, m.traceLaunch(), m.stream);
  };
  if (!fused) {
    m.rays.reserve(std::max<uint64_t>(padded, aoRays));
    m.hits.reserve(padded);
    m.shadowRays.reserve(std::max<uint64_t>(shadowRays, 1));
  }

  const unsigned block = 256;
  cudaStream_t stream = m.stream;
  auto& ev = m.events;
  // Where the frame's passes write (the fused passes list the pixels that found a surface).
  const PassBuffers buffers = m.passes.startFrame(f, aoRays, shadowRays, fused, stream, m.sideStream, ev);
  if (fused) {
    // The vertex normals beside the AO pass, after the shadow pass.
    const auto normals = [&](cudaStream_t side) { enqueueVertexNormals(m, side); };
    const uint32_t* indices = m.indices.data();
    const float* positions = m.positions.data();
    if (blurred)
      if (blur.laterCount > 0)
        enqueueFusedPasses(buffers, f, BlurredTracer<true>{blur}, indices, positions, aoRays, shadowRays, normals);
      else
        enqueueFusedPasses(buffers, f, BlurredTracer<false>{blur}, indices, positions, aoRays, shadowRays, normals);
    else if (scene.cwbvhNodes)
      enqueueFusedPasses(buffers, f, CwbvhTracer{detail::cwbvhView(scene), scene.root}, indices, positions, aoRays,
                         shadowRays, normals);
    else
      enqueueFusedPasses(buffers, f, Bvh2Tracer{scene}, indices, positions, aoRays, shadowRays, normals);
  } else {
    primaryRaysKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.rays.data(), times);
    CUDA_CHECK_LAUNCH("primaryRaysKernel");
    ev.record(1, stream);
    trace(m.rays.data(), f.padded, m.hits.data(), nullptr, buffers.words + kPrimaryCounter);
    ev.record(2, stream);
    surfaceKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.hits.data(), m.indices.data(),
                                                                        m.positions.data(), blur, buffers.surfaces);
    CUDA_CHECK_LAUNCH("surfaceKernel");
    if (aoRays > 0) {
      aoRaysKernel<<<detail::gridFor(aoRays, block), block, 0, stream>>>(f, buffers.surfaces, m.rays.data(), times,
                                                                         buffers.words);
      CUDA_CHECK_LAUNCH("aoRaysKernel");
    }
    ev.record(3, stream);
    trace(m.rays.data(), uint32_t(aoRays), nullptr, buffers.occluded, buffers.words + kAoCounter);
    ev.record(4, stream);
    if (shadowRays > 0) {
      shadowRaysKernel<<<detail::gridFor(shadowRays, block), block, 0, stream>>>(f, buffers.surfaces,
                                                                                 m.shadowRays.data(), times,
                                                                                 buffers.shadowTraced, buffers.words);
      CUDA_CHECK_LAUNCH("shadowRaysKernel");
    }
    ev.record(5, stream);
    trace(m.shadowRays.data(), uint32_t(shadowRays), nullptr, buffers.shadowOccluded, buffers.words + kShadowCounter);
    ev.record(6, stream);
    ev.record(11, stream);
    enqueueVertexNormals(m, stream);
  }
  return shadeAndFinish(buffers, f, FlatShading{m.indices.data(), m.normals.data()}, fused, image, timings);
}

}  // namespace tsah::cuda
