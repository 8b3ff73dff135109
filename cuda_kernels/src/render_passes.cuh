#pragma once
// The GPU renderer's fused passes and its shading, written once for every traced scene: the flat
// runtime's frames (render.cu: one tree, instant or blurred) and two-level scenes
// (two_level_render.cu). The per-pixel math is libtsah's shading.hpp, which the CPU renderer uses
// too. What differs between scenes is a Tracer (a pixel's primary surface, any hits of secondary
// rays) and a Shading (a pixel's colour from its surface, with the smooth normal of the hit).
//
// Fused passes: each thread makes its ray and traces it at once, so no ray or hit buffer is written
// and read back (at 1024 x 768 with 8 AO rays that is about 0.4 GB of traffic per frame). The
// primary pass lists the pixels that found a surface (activePixels), and the AO and shadow passes
// run over that list only: warps take 32 (pixel, sample) entries at a time from a counter until
// the list is done. A small character in a wide frame covers a few percent of the pixels, and one
// thread per padded pixel and sample spent most of those passes on pixels without rays.
//
// A Tracer has kTimed (whether it reads each ray's shutter time), kOwnSurface (whether it computes
// the primary surface itself: surface(ray, time, lighting); otherwise the fused primary pass takes
// its closestHit(ray, time) on the frame's mesh, indices and positions) and anyHit(ray, time).
//
// Compile the including file with -fmad=false, so that the math rounds exactly as on the CPU (see
// shading.hpp); only cosf/sinf/powf/expf (the sample warps and the sRGB curve) can differ from the
// C library in the last bit.
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstdint>

#include "event_timer.hpp"
#include "launch.hpp"
#include "tsah/base/error.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/shading.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace tsah::cuda::detail {

// Pixels are processed in tiles of 8 x 4 (one warp), so a warp's primary rays are coherent.
constexpr uint32_t kTileW = 8, kTileH = 4;
enum RenderWord : uint32_t {
  kAoRays = 0,
  kShadowRays = 1,
  kPrimaryCounter = 2,
  kAoCounter = 3,
  kShadowCounter = 4,
  kActivePixels = 5,  // fused passes: entries of activePixels
  kRenderWords = 6    // the words buffer holds at least this many
};
// Events of a frame: 0 start, 1/2 primary, 3/4 AO, 5/6 shadow, 7 shaded, 8 downloaded, 10 side
// stream joined, 11 shading starts.
constexpr std::size_t kRenderEvents = 12;

struct Frame {
  uint32_t width, height, tilesX, padded;  // padded: tilesX * tilesY * 32 entries
  CameraRays cam;
  SceneLighting light;
  uint32_t aoSamples, shadowSamples;
  SampleKey base;
};

// The frame of the settings: its tiles, camera rays and random-number key. aoRays and shadowRays:
// the secondary rays of every padded pixel. Throws tsah::ConfigError for an empty image size, an
// invalid camera or more than 2^32 - 1 rays in one pass, as the CPU renderer does.
inline Frame makeFrame(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                       uint64_t& aoRays, uint64_t& shadowRays) {
  if (settings.width == 0 || settings.height == 0) throw tsah::ConfigError("render: the image size must be positive");
  validateCamera(camera);
  Frame f;
  f.width = settings.width;
  f.height = settings.height;
  f.tilesX = (f.width + kTileW - 1) / kTileW;
  const uint32_t tilesY = (f.height + kTileH - 1) / kTileH;
  const uint64_t padded = uint64_t(f.tilesX) * tilesY * 32;
  aoRays = padded * settings.aoSamples;
  shadowRays = padded * settings.shadowSamples;
  if (padded > 0xffffffffu || aoRays > 0xffffffffu || shadowRays > 0xffffffffu)
    throw tsah::ConfigError("render: too many rays for one frame");
  f.padded = uint32_t(padded);
  f.cam = cameraRays(camera, f.width, f.height);
  f.light = lighting;
  f.aoSamples = settings.aoSamples;
  f.shadowSamples = settings.shadowSamples;
  f.base = {settings.seed, settings.frame, 0};
  return f;
}

#if defined(__CUDACC__)

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

// The shutter time of a pixel's rays for the tracer (0: an instant tracer reads none).
template <class Tracer>
__device__ __forceinline__ float rayTime(const SampleKey& pixel) {
  if constexpr (Tracer::kTimed) return pixelShutterTime(pixel);
  return 0.0f;
}

// The surface a primary ray finds (indices, positions: the frame's mesh, for tracers without
// surfaces of their own).
template <class Tracer>
__device__ __forceinline__ Surface tracedSurface(const Tracer& tracer, const Ray& ray, const SampleKey& key,
                                                 const uint32_t* indices, const float* positions,
                                                 const SceneLighting& light) {
  if constexpr (Tracer::kOwnSurface)
    return tracer.surface(ray, rayTime<Tracer>(key), light);
  else
    return primarySurface(ray, tracer.closestHit(ray, rayTime<Tracer>(key)), indices, positions, light);
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
  if (pixelOf(f, j, x, y)) s = tracedSurface(tracer, cameraRay(f, x, y), pixelKey(f, j), indices, positions, f.light);
  storeSurface(surfaces, j, s);
  // Listed with one atomic per warp; the order within the list does not matter (every ray's random
  // numbers depend on its pixel and sample only).
  if (s.kind != SurfaceKind::None) activePixels[takeIndices(words + kActivePixels)] = j;
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

// Shading: color(surface, camera ray, ao, visibility, lighting) -> linear colour.
template <class Shading>
__global__ void shadeKernel(Frame f, const float4* __restrict__ surfaces, const uint8_t* __restrict__ aoOccluded,
                            const uint8_t* __restrict__ shadowOccluded, const uint8_t* __restrict__ shadowTraced,
                            Shading shading, uint8_t* __restrict__ image) {
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
  const Vec3 color = shading.color(s, cameraRay(f, x, y), aoFactor(occluded, f.aoSamples),
                                   lightVisibility(visible, f.shadowSamples), f.light);
  storeSrgb8(image + 3 * std::size_t(pixelIndex(f, x, y)), color);
}

#endif  // __CUDACC__

// Where a frame's passes run and what they write (device memory; shadowTraced: one flag per shadow
// ray, whether it was cast).
struct PassBuffers {
  cudaStream_t stream = nullptr;
  cudaStream_t side = nullptr;  // the shadow pass, beside the AO pass
  EventTimer* events = nullptr;  // kRenderEvents of them
  float4* surfaces = nullptr;
  uint32_t* activePixels = nullptr;
  uint32_t* words = nullptr;
  uint8_t* occluded = nullptr;
  uint8_t* shadowOccluded = nullptr;
  uint8_t* shadowTraced = nullptr;
  uint8_t* image = nullptr;  // 3 bytes per pixel
};

// The device buffers behind a frame's PassBuffers, for every renderer (render.cu's flat frames,
// gpu_two_level_render.cpp's two-level ones); each grows when a frame needs more.
class PassBufferSet {
 public:
  // Grows the buffers for frame f (aoRays, shadowRays: makeFrame's; listPixels: with the fused
  // passes' list of the pixels that found a surface), zeroes the ray counters on `stream` and
  // records event 0 (the frame's start) there. The passes run on `stream` and `side`.
  PassBuffers startFrame(const Frame& f, uint64_t aoRays, uint64_t shadowRays, bool listPixels, cudaStream_t stream,
                         cudaStream_t side, EventTimer& events) {
    surfaces_.reserve(3 * uint64_t(f.padded));
    if (listPixels) activePixels_.reserve(f.padded);
    occluded_.reserve(std::max<uint64_t>(aoRays, 1));
    shadowOccluded_.reserve(std::max<uint64_t>(2 * shadowRays, 2));  // results, then "traced" flags
    image_.reserve(std::size_t(f.width) * f.height * 3);
    words_.reserve(kRenderWords);
    words_.fillBytes(0, stream);
    events.record(0, stream);
    PassBuffers b;
    b.stream = stream;
    b.side = side;
    b.events = &events;
    b.surfaces = surfaces_.data();
    b.activePixels = activePixels_.data();
    b.words = words_.data();
    b.occluded = occluded_.data();
    b.shadowOccluded = shadowOccluded_.data();
    b.shadowTraced = shadowOccluded_.data() + shadowRays;
    b.image = image_.data();
    return b;
  }
  // The last frame's surfaces (3 float4 per padded pixel).
  const float4* surfaces() const { return surfaces_.data(); }

 private:
  DeviceBuffer<uint32_t> words_, activePixels_;
  DeviceBuffer<float4> surfaces_;  // 3 per pixel: position + kind, normal + triangle, u v
  DeviceBuffer<uint8_t> occluded_, shadowOccluded_, image_;
};

#if defined(__CUDACC__)

// The three fused passes (events 1/2, 3/4, 5/6 around them, so a pass's time includes making its
// rays), then sideWork(side stream) after the shadow pass; event 11 marks the start of shading.
template <class Tracer, class SideWork>
void enqueueFusedPasses(const PassBuffers& b, const Frame& f, const Tracer& tracer, const uint32_t* indices,
                        const float* positions, uint64_t aoRays, uint64_t shadowRays, SideWork&& sideWork) {
  cudaStream_t stream = b.stream;
  EventTimer& ev = *b.events;
  const unsigned block = 128;  // fixed by __launch_bounds__
  ev.record(1, stream);
  fusedPrimaryKernel<<<gridFor(f.padded, block), block, 0, stream>>>(f, tracer, indices, positions, b.surfaces,
                                                                     b.activePixels, b.words);
  CUDA_CHECK_LAUNCH("fusedPrimaryKernel");
  ev.record(2, stream);
  ev.record(3, stream);
  // The secondary passes loop over the listed pixels (their number is known on the device only):
  // as many blocks as are resident at once, or fewer when the frame cannot have that many rays.
  auto listGrid = [&](auto kernel, uint64_t rays) {
    const int resident = residentBlocks(kernel, int(block), 16);
    return std::min<unsigned>(unsigned(resident), gridFor(rays, block));
  };
  // The shadow pass (then sideWork) runs on the side stream beside the AO pass: both only read the
  // surfaces, and each alone leaves most of the GPU idle on small frames (a few thousand warps of
  // long any-hit rays). Event 10 joins them before shading.
  cudaStream_t side = b.side;
  ev.streamWait(2, side);
  if (aoRays > 0) {
    fusedAoKernel<Tracer><<<listGrid(fusedAoKernel<Tracer>, aoRays), block, 0, stream>>>(
        f, tracer, b.surfaces, b.activePixels, b.occluded, b.words);
    CUDA_CHECK_LAUNCH("fusedAoKernel");
  }
  ev.record(4, stream);
  ev.record(5, side);
  if (shadowRays > 0) {
    fusedShadowKernel<Tracer><<<listGrid(fusedShadowKernel<Tracer>, shadowRays), block, 0, side>>>(
        f, tracer, b.surfaces, b.activePixels, b.shadowOccluded, b.shadowTraced, b.words);
    CUDA_CHECK_LAUNCH("fusedShadowKernel");
  }
  ev.record(6, side);
  sideWork(side);
  ev.record(10, side);
  ev.streamWait(10, stream);
  ev.record(11, stream);
}

// After the passes (event 11 recorded): shading (to event 7), the image's download into `image`
// (when not null; to event 8), the ray counts; waits for the frame. The stats and timings of the
// frame (fused: the rays are made inside the trace passes, and 4 -> 5 spans two streams).
template <class Shading>
RenderStats shadeAndFinish(const PassBuffers& b, const Frame& f, const Shading& shading, bool fused, Image* image,
                           GpuRenderTimings* timings) {
  cudaStream_t stream = b.stream;
  EventTimer& ev = *b.events;
  const unsigned block = 256;
  shadeKernel<<<gridFor(f.padded, block), block, 0, stream>>>(f, b.surfaces, b.occluded, b.shadowOccluded,
                                                              b.shadowTraced, shading, b.image);
  CUDA_CHECK_LAUNCH("shadeKernel");
  ev.record(7, stream);
  if (image) {
    if (image->width != f.width || image->height != f.height) *image = Image(f.width, f.height);
    CUDA_CHECK(cudaMemcpyAsync(image->rgb.data(), b.image, image->rgb.size(), cudaMemcpyDeviceToHost, stream));
  }
  ev.record(8, stream);
  uint32_t counts[2] = {0, 0};
  CUDA_CHECK(cudaMemcpyAsync(counts, b.words, sizeof counts, cudaMemcpyDeviceToHost, stream));
  CUDA_CHECK(cudaStreamSynchronize(stream));

  RenderStats stats;
  stats.primary = {uint64_t(f.width) * f.height, ev.ms(1, 2)};
  stats.ao = {counts[kAoRays], ev.ms(3, 4)};
  stats.shadow = {counts[kShadowRays], ev.ms(5, 6)};
  stats.shadeMs = ev.ms(11, 7);
  if (timings) {
    timings->generateMs = ev.ms(0, 1) + ev.ms(2, 3) + (fused ? 0.0 : ev.ms(4, 5));
    timings->shadeMs = stats.shadeMs;
    timings->downloadMs = ev.ms(7, 8);
    timings->totalMs = ev.ms(0, 8);
  }
  return stats;
}

#endif  // __CUDACC__

}  // namespace tsah::cuda::detail
