// tsah::renderFrame on the GPU: the same three ray passes (primary closest hit, ambient occlusion,
// shadows), one kernel per step. The per-pixel math (camera rays, the primary surface, the AO and
// shadow rays, vertex normals, shading) is libtsah's shading.hpp, which the CPU renderer uses too.
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
#include "runtime_impl.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/shading.hpp"

namespace tsah::cuda {

namespace {

using detail::RootInfo;

// Pixels are processed in tiles of 8 x 4 (one warp), so a warp's primary rays are coherent.
constexpr uint32_t kTileW = 8, kTileH = 4;
enum Word : uint32_t {
  kAoRays = 0,
  kShadowRays = 1,
  kPrimaryCounter = 2,
  kAoCounter = 3,
  kShadowCounter = 4,
  kActivePixels = 5,  // fused passes: entries of activePixels
  kWords = 6          // GpuRuntime::Impl::words holds at least this many
};

struct Frame {
  uint32_t width, height, tilesX, padded;  // padded: tilesX * tilesY * 32 entries
  CameraRays cam;
  SceneLighting light;
  uint32_t aoSamples, shadowSamples;
  SampleKey base;
};

__device__ __forceinline__ bool pixelOf(const Frame& f, uint32_t j, uint32_t& x, uint32_t& y) {
  const uint32_t tile = j >> 5, within = j & 31u;
  x = (tile % f.tilesX) * kTileW + (within % kTileW);
  y = (tile / f.tilesX) * kTileH + (within / kTileW);
  return x < f.width && y < f.height;
}

__device__ __forceinline__ uint32_t pixelIndex(const Frame& f, uint32_t x, uint32_t y) { return y * f.width + x; }

__device__ __forceinline__ Ray cameraRay(const Frame& f, uint32_t x, uint32_t y) {
  return f.cam.ray(float(x) + 0.5f, float(y) + 0.5f);
}

// The random-number key of padded pixel j (its pixel index in the image).
__device__ __forceinline__ SampleKey pixelKey(const Frame& f, uint32_t j) {
  uint32_t x, y;
  pixelOf(f, j, x, y);
  SampleKey key = f.base;
  key.pixel = pixelIndex(f, x, y);
  return key;
}

// A blurred frame: the view of its keys (keyCount >= 2); an instant frame has keyCount 0.
__device__ __forceinline__ bool isBlurred(const MotionBvhView& view) { return view.keyCount >= 2; }

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

__device__ __forceinline__ void countRays(uint32_t* word, bool valid) {
  const unsigned mask = __ballot_sync(__activemask(), valid);
  const uint32_t lane = threadIdx.x & 31u;
  if (valid && lane == uint32_t(__ffs(mask) - 1)) atomicAdd(word, uint32_t(__popc(mask)));
}

// A Surface as three float4 per padded pixel (coalesced 16-byte accesses). A pixel without a
// surface stores (and its readers load) only the first, which holds the kind: on a small mesh in a
// wide frame that is most pixels.
__device__ __forceinline__ void storeSurface(float4* surfaces, uint32_t j, const Surface& s) {
  float4* out = surfaces + 3 * std::size_t(j);
  out[0] = make_float4(s.position.x, s.position.y, s.position.z, __uint_as_float(uint32_t(s.kind)));
  if (s.kind == SurfaceKind::None) return;
  out[1] = make_float4(s.normal.x, s.normal.y, s.normal.z, __uint_as_float(s.tri));
  out[2] = make_float4(s.u, s.v, 0.0f, 0.0f);
}

__device__ __forceinline__ Surface loadSurface(const float4* surfaces, uint32_t j) {
  const float4* p = surfaces + 3 * std::size_t(j);
  const float4 a = p[0];
  if (SurfaceKind(__float_as_uint(a.w)) == SurfaceKind::None) return Surface{};
  const float4 b = p[1], c = p[2];
  return {{a.x, a.y, a.z}, {b.x, b.y, b.z}, SurfaceKind(__float_as_uint(a.w)), __float_as_uint(b.w), c.x, c.y};
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
// frame (view): the hit triangle at the pixel's time.
__global__ void surfaceKernel(Frame f, const Hit* __restrict__ hits, const uint32_t* __restrict__ indices,
                              const float* __restrict__ positions, MotionBvhView view, float4* __restrict__ surfaces) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  Surface s;
  if (pixelOf(f, j, x, y))
    s = isBlurred(view) ? blurredPrimarySurface(cameraRay(f, x, y), hits[j], view, pixelShutterTime(pixelKey(f, j)),
                                                f.light)
                        : primarySurface(cameraRay(f, x, y), hits[j], indices, positions, f.light);
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

// Fused passes: each thread makes its ray and traces it at once (the layout's per-ray traversal:
// bvh2ClosestHit / bvh2AnyHit, or the TSAH_HD cwbvhClosestHit / cwbvhAnyHit), so no ray or hit
// buffer is written and read back (at 1024 x 768 with 8 AO rays that is about 0.4 GB of traffic per
// frame). Same rays, same results as the separate kernels above.
//
// The primary pass lists the pixels that found a surface (activePixels), and the AO and shadow
// passes run over that list only: warps take 32 (pixel, sample) entries at a time from a counter
// until the list is done. A small character in a wide frame covers a few percent of the pixels,
// and one thread per padded pixel and sample spent most of those passes on pixels without rays.
//
// Every tracer takes each ray's shutter time; kTimed: whether it reads it (the instant tracers do
// not, and the kernels then compute no time).
struct Bvh2Tracer {
  static constexpr bool kTimed = false;
  detail::TraceScene scene;
  __device__ __forceinline__ Hit closestHit(const Ray& ray, float) const {
    return detail::bvh2ClosestHit(scene, *scene.root, ray);
  }
  __device__ __forceinline__ bool anyHit(const Ray& ray, float) const {
    return detail::bvh2AnyHit(scene, *scene.root, ray);
  }
};

struct CwbvhTracer {
  static constexpr bool kTimed = false;
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

// A blurred frame: the traversal of the blurred batch queries at the ray's time.
// The surface of a primary hit lerps the hit triangle through the key arrays (view).
struct BlurredTracer {
  static constexpr bool kTimed = true;
  detail::BlurredLayout layout;
  MotionBvhView view;
  __device__ __forceinline__ Hit closestHit(const Ray& ray, float time) const {
    return detail::bvh2BlurredClosestHit(layout, ray, time);
  }
  __device__ __forceinline__ bool anyHit(const Ray& ray, float time) const {
    return detail::bvh2BlurredAnyHit(layout, ray, time);
  }
};

// The shutter time of a pixel's rays for the tracer (0: an instant tracer reads none).
template <class Tracer>
__device__ __forceinline__ float rayTime(const SampleKey& pixel) {
  if constexpr (Tracer::kTimed) return pixelShutterTime(pixel);
  return 0.0f;
}

template <class Tracer>
__global__ void __launch_bounds__(128) fusedPrimaryKernel(Frame f, Tracer tracer, const uint32_t* __restrict__ indices,
                                                          const float* __restrict__ positions,
                                                          float4* __restrict__ surfaces,
                                                          uint32_t* __restrict__ activePixels,
                                                          uint32_t* __restrict__ words) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  Surface s;
  if (pixelOf(f, j, x, y)) {
    const Ray ray = cameraRay(f, x, y);
    if constexpr (Tracer::kTimed) {
      const float time = rayTime<Tracer>(pixelKey(f, j));
      s = blurredPrimarySurface(ray, tracer.closestHit(ray, time), tracer.view, time, f.light);
    } else {
      s = primarySurface(ray, tracer.closestHit(ray, 0.0f), indices, positions, f.light);
    }
  }
  storeSurface(surfaces, j, s);
  // Listed with one atomic per warp; the order within the list does not matter (every ray's random
  // numbers depend on its pixel and sample only).
  if (s.kind != SurfaceKind::None) activePixels[detail::takeIndices(words + kActivePixels)] = j;
}

// Calls body(pixel, sample) for every sample of every listed pixel: each warp takes 32 entries at
// a time from *counter. Every lane of the warp must call it (the grid has no partial warps).
template <class Body>
__device__ __forceinline__ void forEachListedSample(const uint32_t* __restrict__ activePixels, const uint32_t* words,
                                                    uint32_t* counter, uint32_t samples, Body body) {
  const uint32_t total = words[kActivePixels] * samples;  // < 2^32: at most padded * samples entries
  const uint32_t lane = threadIdx.x & 31u;
  for (;;) {
    uint32_t base = 0;
    if (lane == 0) base = atomicAdd(counter, 32u);
    base = __shfl_sync(0xffffffffu, base, 0);
    if (base >= total) return;
    const uint32_t r = base + lane;
    if (r < total) body(__ldg(activePixels + r / samples), r % samples);
  }
}

template <class Tracer>
__global__ void __launch_bounds__(128) fusedAoKernel(Frame f, Tracer tracer, const float4* __restrict__ surfaces,
                                                     const uint32_t* __restrict__ activePixels,
                                                     uint8_t* __restrict__ occluded, uint32_t* __restrict__ words) {
  forEachListedSample(activePixels, words, words + kAoCounter, f.aoSamples, [&](uint32_t j, uint32_t sample) {
    const Surface s = loadSurface(surfaces, j);
    const SampleKey key = pixelKey(f, j);
    countRays(words + kAoRays, true);
    occluded[std::size_t(j) * f.aoSamples + sample] =
        tracer.anyHit(aoRay(s, key, sample, f.light.aoDistance), rayTime<Tracer>(key)) ? 1 : 0;
  });
}

template <class Tracer>
__global__ void __launch_bounds__(128) fusedShadowKernel(Frame f, Tracer tracer, const float4* __restrict__ surfaces,
                                                         const uint32_t* __restrict__ activePixels,
                                                         uint8_t* __restrict__ occluded, uint8_t* __restrict__ traced,
                                                         uint32_t* __restrict__ words) {
  forEachListedSample(activePixels, words, words + kShadowCounter, f.shadowSamples, [&](uint32_t j, uint32_t sample) {
    const Surface s = loadSurface(surfaces, j);
    const SampleKey key = pixelKey(f, j);
    Ray ray;
    // A light point behind the surface: no ray, not lit.
    const bool valid = shadowRay(s, f.light, key, sample, ray);
    countRays(words + kShadowRays, valid);
    const std::size_t r = std::size_t(j) * f.shadowSamples + sample;
    traced[r] = valid ? 1 : 0;
    occluded[r] = valid && tracer.anyHit(ray, rayTime<Tracer>(key)) ? 1 : 0;
  });
}

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

__global__ void shadeKernel(Frame f, const float4* __restrict__ surfaces, const uint8_t* __restrict__ aoOccluded,
                            const uint8_t* __restrict__ shadowOccluded, const uint8_t* __restrict__ shadowTraced,
                            const uint32_t* __restrict__ indices, const float* __restrict__ normals,
                            uint8_t* __restrict__ image) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  if (!pixelOf(f, j, x, y)) return;
  const Surface s = loadSurface(surfaces, j);
  uint32_t occluded = 0, visible = 0;
  if (s.kind != SurfaceKind::None) {
    for (uint32_t k = 0; k < f.aoSamples; ++k) occluded += aoOccluded[std::size_t(j) * f.aoSamples + k];
    for (uint32_t k = 0; k < f.shadowSamples; ++k) {
      const std::size_t r = std::size_t(j) * f.shadowSamples + k;
      visible += shadowTraced[r] && !shadowOccluded[r] ? 1u : 0u;
    }
  }
  const Vec3 color = pixelColor(s, cameraRay(f, x, y), aoFactor(occluded, f.aoSamples),
                                lightVisibility(visible, f.shadowSamples), indices, normals, f.light);
  storeSrgb8(image + 3 * std::size_t(pixelIndex(f, x, y)), color);
}

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

// The three fused passes (events 1/2, 3/4, 5/6 around them, so a pass's time includes making its
// rays), then the vertex normals; event 11 marks the start of shading.
template <class Tracer>
void enqueueFusedPasses(GpuRuntime::Impl& m, const Frame& f, const Tracer& tracer, uint64_t aoRays,
                        uint64_t shadowRays, uint8_t* shadowTraced) {
  cudaStream_t stream = m.stream;
  auto& ev = m.events;
  const unsigned block = 128;  // fixed by __launch_bounds__
  ev.record(1, stream);
  fusedPrimaryKernel<<<detail::gridFor(f.padded, block), block, 0, stream>>>(
      f, tracer, m.indices.data(), m.positions.data(), m.surfaces.data(), m.activePixels.data(), m.words.data());
  CUDA_CHECK_LAUNCH("fusedPrimaryKernel");
  ev.record(2, stream);
  ev.record(3, stream);
  // The secondary passes loop over the listed pixels (their number is known on the device only):
  // as many blocks as are resident at once, or fewer when the frame cannot have that many rays.
  auto listGrid = [&](auto kernel, uint64_t rays) {
    const int resident = detail::residentBlocks(kernel, int(block), 16);
    return std::min<unsigned>(unsigned(resident), detail::gridFor(rays, block));
  };
  // The shadow pass (then the vertex normals) runs on the side stream beside the AO pass: both
  // only read the surfaces, and each alone leaves most of the GPU idle on small frames (a few
  // thousand warps of long any-hit rays). Event 10 joins them before shading.
  cudaStream_t side = m.sideStream;
  ev.streamWait(2, side);
  if (aoRays > 0) {
    fusedAoKernel<Tracer><<<listGrid(fusedAoKernel<Tracer>, aoRays), block, 0, stream>>>(
        f, tracer, m.surfaces.data(), m.activePixels.data(), m.occluded.data(), m.words.data());
    CUDA_CHECK_LAUNCH("fusedAoKernel");
  }
  ev.record(4, stream);
  ev.record(5, side);
  if (shadowRays > 0) {
    fusedShadowKernel<Tracer><<<listGrid(fusedShadowKernel<Tracer>, shadowRays), block, 0, side>>>(
        f, tracer, m.surfaces.data(), m.activePixels.data(), m.shadowOccluded.data(), shadowTraced, m.words.data());
    CUDA_CHECK_LAUNCH("fusedShadowKernel");
  }
  ev.record(6, side);
  enqueueVertexNormals(m, side);
  ev.record(10, side);
  ev.streamWait(10, stream);
  ev.record(11, stream);
}

}  // namespace

RenderStats renderFrameGpu(GpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                           const RenderSettings& settings, Image* image, GpuRenderTimings* timings) {
  if (settings.width == 0 || settings.height == 0) throw tsah::ConfigError("render: the image size must be positive");
  validateCamera(camera);
  GpuRuntime::Impl& m = *runtime.impl_;
  m.requireTraceable();

  Frame f;
  f.width = settings.width;
  f.height = settings.height;
  f.tilesX = (f.width + kTileW - 1) / kTileW;
  const uint32_t tilesY = (f.height + kTileH - 1) / kTileH;
  const uint64_t padded = uint64_t(f.tilesX) * tilesY * 32;
  const uint64_t aoRays = padded * settings.aoSamples, shadowRays = padded * settings.shadowSamples;
  if (padded > 0xffffffffu || aoRays > 0xffffffffu || shadowRays > 0xffffffffu)
    throw tsah::ConfigError("render: too many rays for one frame");
  f.padded = uint32_t(padded);
  f.cam = cameraRays(camera, f.width, f.height);
  f.light = lighting;
  f.aoSamples = settings.aoSamples;
  f.shadowSamples = settings.shadowSamples;
  f.base = {settings.seed, settings.frame, 0};

  // Fused passes (Config::fusePasses) need no ray or hit buffers.
  const detail::TraceScene scene = m.scene();
  const bool fused = m.config.fusePasses;
  // A blurred frame traces its key arrays (keyCount 0: the instant frame).
  const bool blurred = runtime.blurred();
  const MotionBvhView blur = blurred ? m.motionView() : MotionBvhView{};
  const detail::BlurredLayout blurLayout = blurred ? m.blurredLayout() : detail::BlurredLayout{};
  float* times = nullptr;  // separate passes of a blurred frame: each ray's shutter time
  if (blurred && !fused) {
    m.rayTimes.reserve(std::max({padded, aoRays, shadowRays}));
    times = m.rayTimes.data();
  }
  // The separate passes' trace: the instant frame's kernel, or the blurred traversal at each ray's time.
  auto trace = [&](const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded, uint32_t* counter) {
    if (blurred)
      detail::launchBlurredTrace(blurLayout, rays, times, count, hits, occluded, m.stream);
    else
      detail::launchTrace(scene, rays, count, hits, occluded, counter, m.traceLaunch(), m.stream);
  };
  if (!fused) {
    m.rays.reserve(std::max<uint64_t>(padded, aoRays));
    m.hits.reserve(padded);
  }
  m.surfaces.reserve(3 * padded);
  if (fused) m.activePixels.reserve(padded);
  m.occluded.reserve(std::max<uint64_t>(aoRays, 1));
  if (!fused) m.shadowRays.reserve(std::max<uint64_t>(shadowRays, 1));
  m.shadowOccluded.reserve(std::max<uint64_t>(2 * shadowRays, 2));  // results, then "traced" flags
  m.image.reserve(std::size_t(f.width) * f.height * 3);
  uint8_t* shadowTraced = m.shadowOccluded.data() + shadowRays;

  const unsigned block = 256;
  cudaStream_t stream = m.stream;
  auto& ev = m.events;


  m.words.reserve(kWords);
  m.words.fillBytes(0, stream);
  ev.record(0, stream);
  if (fused) {
    if (blurred)
      enqueueFusedPasses(m, f, BlurredTracer{blurLayout, blur}, aoRays, shadowRays, shadowTraced);
    else if (scene.cwbvhNodes)
      enqueueFusedPasses(m, f, CwbvhTracer{detail::cwbvhView(scene), scene.root}, aoRays, shadowRays, shadowTraced);
    else
      enqueueFusedPasses(m, f, Bvh2Tracer{scene}, aoRays, shadowRays, shadowTraced);
  } else {
    primaryRaysKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.rays.data(), times);
    CUDA_CHECK_LAUNCH("primaryRaysKernel");
    ev.record(1, stream);
    trace(m.rays.data(), f.padded, m.hits.data(), nullptr, m.words.data() + kPrimaryCounter);
    ev.record(2, stream);
    surfaceKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.hits.data(), m.indices.data(),
                                                                        m.positions.data(), blur, m.surfaces.data());
    CUDA_CHECK_LAUNCH("surfaceKernel");
    if (aoRays > 0) {
      aoRaysKernel<<<detail::gridFor(aoRays, block), block, 0, stream>>>(f, m.surfaces.data(), m.rays.data(), times,
                                                                         m.words.data());
      CUDA_CHECK_LAUNCH("aoRaysKernel");
    }
    ev.record(3, stream);
    trace(m.rays.data(), uint32_t(aoRays), nullptr, m.occluded.data(), m.words.data() + kAoCounter);
    ev.record(4, stream);
    if (shadowRays > 0) {
      shadowRaysKernel<<<detail::gridFor(shadowRays, block), block, 0, stream>>>(f, m.surfaces.data(),
                                                                                 m.shadowRays.data(), times,
                                                                                 shadowTraced, m.words.data());
      CUDA_CHECK_LAUNCH("shadowRaysKernel");
    }
    ev.record(5, stream);
    trace(m.shadowRays.data(), uint32_t(shadowRays), nullptr, m.shadowOccluded.data(), m.words.data() + kShadowCounter);
    ev.record(6, stream);
  }
  if (!fused) {
    ev.record(11, stream);
    enqueueVertexNormals(m, stream);
  }
  shadeKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.surfaces.data(), m.occluded.data(),
                                                                    m.shadowOccluded.data(), shadowTraced,
                                                                    m.indices.data(), m.normals.data(),
                                                                    m.image.data());
  CUDA_CHECK_LAUNCH("shadeKernel");
  ev.record(7, stream);
  if (image) {
    if (image->width != f.width || image->height != f.height) *image = Image(f.width, f.height);
    CUDA_CHECK(cudaMemcpyAsync(image->rgb.data(), m.image.data(), image->rgb.size(), cudaMemcpyDeviceToHost, stream));
  }
  ev.record(8, stream);
  uint32_t counts[2] = {0, 0};
  CUDA_CHECK(cudaMemcpyAsync(counts, m.words.data(), sizeof counts, cudaMemcpyDeviceToHost, stream));
  CUDA_CHECK(cudaStreamSynchronize(stream));

  RenderStats stats;
  stats.primary = {uint64_t(f.width) * f.height, ev.ms(1, 2)};
  stats.ao = {counts[kAoRays], ev.ms(3, 4)};
  stats.shadow = {counts[kShadowRays], ev.ms(5, 6)};
  stats.shadeMs = ev.ms(11, 7);
  if (timings) {  // fused: the rays are made inside the trace passes (and 4 -> 5 spans two streams)
    timings->generateMs = ev.ms(0, 1) + ev.ms(2, 3) + (fused ? 0.0 : ev.ms(4, 5));
    timings->shadeMs = stats.shadeMs;
    timings->downloadMs = ev.ms(7, 8);
    timings->totalMs = ev.ms(0, 8);
  }
  return stats;
}

}  // namespace tsah::cuda
