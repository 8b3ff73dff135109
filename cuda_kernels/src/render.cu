// tsah::renderFrame on the GPU: the same three ray passes (primary closest hit, ambient occlusion,
// shadows), the same per-sample random numbers and the same shading, one kernel per step.
//
// Compiled with -fmad=false, and normalizing with IEEE square roots and divisions, so camera rays,
// surfaces and secondary rays are computed with the CPU's exact roundings; only cosf/sinf/powf/expf
// (used by the sample warps and the sRGB curve) can differ from the C library in the last bit.
// The shading of renderer.cpp lives in its anonymous namespace, so it is repeated here (kernels
// surfaceKernel, vertexNormalsKernel, shadeKernel): keep the two in step.
#include <cuda/atomic>

#include "anim/error.hpp"
#include "kernels.hpp"
#include "launch.hpp"
#include "runtime_impl.hpp"
#include "tsah/camera.hpp"
#include "tsah/sampling.hpp"

namespace tsah::cuda {

namespace {

using detail::RootInfo;

// Pixels are processed in tiles of 8 x 4 (one warp), so a warp's primary rays are coherent.
constexpr uint32_t kTileW = 8, kTileH = 4;
constexpr uint32_t kDimAo = 0, kDimShadow = 2;  // renderer.cpp's sample dimensions
enum SurfaceKind : uint32_t { kNone = 0, kMesh = 1, kGround = 2 };
enum Word : uint32_t { kAoRays = 0, kShadowRays = 1, kPrimaryCounter = 2, kAoCounter = 3, kShadowCounter = 4 };

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

// normalize() of sampling.hpp with the host's arithmetic (it uses rsqrtf on the device).
__device__ __forceinline__ Vec3 normalizeExact(Vec3 v) {
  const float len2 = dot(v, v);
  if (!(len2 > 0.0f)) return {0.0f, 0.0f, 1.0f};
  return v * (1.0f / sqrtf(len2));
}

__device__ __forceinline__ Ray cameraRay(const CameraRays& c, float px, float py) {
  Ray r;
  r.org = c.eye;
  r.dir = normalizeExact(c.corner + c.dx * px + c.dy * py);
  r.tmin = 0.0f;
  r.tmax = 3.402823466e38f;
  return r;
}

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

__device__ __forceinline__ Vec3 loadVertex(const float* p, uint32_t v) {
  return {p[3 * std::size_t(v)], p[3 * std::size_t(v) + 1], p[3 * std::size_t(v) + 2]};
}

__global__ void primaryRaysKernel(Frame f, Ray* __restrict__ rays) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  storeRay(rays, j, pixelOf(f, j, x, y) ? cameraRay(f.cam, float(x) + 0.5f, float(y) + 0.5f) : noRay());
}

// The primary pass's surface (renderer.cpp): mesh hit or the analytic ground, offset along the normal.
__global__ void surfaceKernel(Frame f, const Hit* __restrict__ hits, const uint32_t* __restrict__ indices,
                              const float* __restrict__ positions, float4* __restrict__ surfaces) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  Vec3 position{0, 0, 0}, normal{0, 0, 1};
  uint32_t kind = kNone, tri = 0;
  float u = 0.0f, v = 0.0f;
  if (pixelOf(f, j, x, y)) {
    const Ray ray = cameraRay(f.cam, float(x) + 0.5f, float(y) + 0.5f);
    const Hit hit = hits[j];
    const Vec3 up = f.light.up;
    float tGround = 3.402823466e38f;
    if (f.light.ground) {
      const float denom = dot(ray.dir, up);
      if (denom < 0.0f) {
        const float t = (f.light.groundHeight - dot(ray.org, up)) / denom;
        if (t > 0.0f) tGround = t;
      }
    }
    if (hit.valid() && hit.t <= tGround) {
      const uint32_t* t3 = indices + 3 * std::size_t(hit.tri);
      const Vec3 v0 = loadVertex(positions, t3[0]), v1 = loadVertex(positions, t3[1]),
                 v2 = loadVertex(positions, t3[2]);
      Vec3 n = normalizeExact(cross(v1 - v0, v2 - v0));
      if (dot(n, ray.dir) > 0.0f) n = n * -1.0f;
      const Vec3 p = v0 * (1.0f - hit.u - hit.v) + v1 * hit.u + v2 * hit.v;
      position = p + n * f.light.epsilon;
      normal = n;
      kind = kMesh;
      tri = hit.tri;
      u = hit.u;
      v = hit.v;
    } else if (tGround < 3.402823466e38f) {
      position = ray.org + ray.dir * tGround + up * f.light.epsilon;
      normal = up;
      kind = kGround;
    }
  }
  float4* out = surfaces + 3 * std::size_t(j);
  out[0] = make_float4(position.x, position.y, position.z, __uint_as_float(kind));
  out[1] = make_float4(normal.x, normal.y, normal.z, __uint_as_float(tri));
  out[2] = make_float4(u, v, 0.0f, 0.0f);
}

// What the primary pass found at a pixel (renderer.cpp's Surface).
struct Surface {
  Vec3 position;  // already offset along the normal
  Vec3 normal;    // geometric, unit, facing the camera
  uint32_t kind;
  uint32_t tri;   // mesh hits: triangle and barycentrics, for the smooth shading normal
  float u, v;
};

__device__ __forceinline__ Surface loadSurface(const float4* surfaces, uint32_t j) {
  const float4* p = surfaces + 3 * std::size_t(j);
  const float4 a = p[0], b = p[1], c = p[2];
  return {{a.x, a.y, a.z}, {b.x, b.y, b.z}, __float_as_uint(a.w), __float_as_uint(b.w), c.x, c.y};
}

__device__ __forceinline__ uint32_t pixelIndex(const Frame& f, uint32_t x, uint32_t y) { return y * f.width + x; }

__global__ void aoRaysKernel(Frame f, const float4* __restrict__ surfaces, Ray* __restrict__ rays,
                             uint32_t* __restrict__ words) {
  const uint64_t r = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const uint64_t total = uint64_t(f.padded) * f.aoSamples;
  if (r >= total) return;
  const uint32_t j = uint32_t(r / f.aoSamples), k = uint32_t(r % f.aoSamples);
  uint32_t x, y;
  const bool inside = pixelOf(f, j, x, y);
  const Surface s = loadSurface(surfaces, j);
  const bool valid = inside && s.kind != kNone;
  Ray ray = noRay();
  if (valid) {
    SampleKey key = f.base;
    key.pixel = pixelIndex(f, x, y);
    ray.org = s.position;
    ray.dir = cosineHemisphere(s.normal, sampleUniform(key, k, kDimAo), sampleUniform(key, k, kDimAo + 1));
    ray.tmin = 0.0f;
    ray.tmax = f.light.aoDistance;
  }
  storeRay(rays, r, ray);
  countRays(words + kAoRays, valid);
}

__global__ void shadowRaysKernel(Frame f, const float4* __restrict__ surfaces, Ray* __restrict__ rays,
                                 uint8_t* __restrict__ traced, uint32_t* __restrict__ words) {
  const uint64_t r = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const uint64_t total = uint64_t(f.padded) * f.shadowSamples;
  if (r >= total) return;
  const uint32_t j = uint32_t(r / f.shadowSamples), k = uint32_t(r % f.shadowSamples);
  uint32_t x, y;
  const bool inside = pixelOf(f, j, x, y);
  const Surface s = loadSurface(surfaces, j);
  Ray ray = noRay();
  bool valid = false;
  if (inside && s.kind != kNone) {
    SampleKey key = f.base;
    key.pixel = pixelIndex(f, x, y);
    const Vec3 axis = normalizeExact(f.light.lightCenter - s.position);
    const Vec3 q = sampleDisk(f.light.lightCenter, axis, f.light.lightRadius, sampleUniform(key, k, kDimShadow),
                              sampleUniform(key, k, kDimShadow + 1));
    const Vec3 dir = q - s.position;
    if (dot(dir, s.normal) > 0.0f) {  // a light point behind the surface: no ray, not lit
      ray.org = s.position;
      ray.dir = dir;
      ray.tmin = 0.0f;
      ray.tmax = 1.0f;
      valid = true;
    }
  }
  storeRay(rays, r, ray);
  traced[r] = valid ? 1 : 0;
  countRays(words + kShadowRays, valid);
}

// Area-weighted vertex normals of the current frame (renderer.cpp's vertexNormals, for shading
// only): each vertex sums the face normals of its triangles in increasing triangle order, as the
// CPU loop does, so the sums are bit-identical. vertexTris: the triangles of each vertex (CSR).
__global__ void vertexNormalsKernel(uint32_t vertices, const uint32_t* __restrict__ offsets,
                                    const uint32_t* __restrict__ vertexTris, const uint32_t* __restrict__ indices,
                                    const float* __restrict__ positions, float* __restrict__ normals) {
  const uint32_t vtx = blockIdx.x * blockDim.x + threadIdx.x;
  if (vtx >= vertices) return;
  Vec3 n{0, 0, 0};
  for (uint32_t k = offsets[vtx]; k < offsets[vtx + 1]; ++k) {
    const uint32_t* t3 = indices + 3 * std::size_t(vertexTris[k]);
    const Vec3 v0 = loadVertex(positions, t3[0]);
    n = n + cross(loadVertex(positions, t3[1]) - v0, loadVertex(positions, t3[2]) - v0);
  }
  normals[3 * std::size_t(vtx)] = n.x;
  normals[3 * std::size_t(vtx) + 1] = n.y;
  normals[3 * std::size_t(vtx) + 2] = n.z;
}

// renderer.cpp's shading.
__device__ __forceinline__ Vec3 mix(Vec3 a, Vec3 b, float s) { return a + (b - a) * s; }
__device__ __forceinline__ Vec3 mul(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

__device__ Vec3 skyColor(Vec3 dir, Vec3 up) {
  const float h = dot(dir, up);
  const Vec3 horizon{0.80f, 0.85f, 0.91f}, zenith{0.30f, 0.48f, 0.78f}, below{0.40f, 0.39f, 0.37f};
  if (h < 0.0f) return mix(horizon, below, fminf(1.0f, -h * 4.0f));
  return mix(horizon, zenith, sqrtf(h));
}

__device__ uint8_t toSrgb8(float linear) {
  const float c = fminf(fmaxf(linear, 0.0f), 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(lroundf(s * 255.0f));
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
  const Vec3 up = f.light.up;
  Vec3 color;
  if (s.kind == kNone) {
    color = skyColor(cameraRay(f.cam, float(x) + 0.5f, float(y) + 0.5f).dir, up);
  } else {
    float ao = 1.0f, visibility = 1.0f;
    if (f.aoSamples > 0) {
      uint32_t occluded = 0;
      for (uint32_t k = 0; k < f.aoSamples; ++k) occluded += aoOccluded[std::size_t(j) * f.aoSamples + k];
      ao = 1.0f - float(occluded) / float(f.aoSamples);
    }
    if (f.shadowSamples > 0) {
      uint32_t visible = 0;
      for (uint32_t k = 0; k < f.shadowSamples; ++k) {
        const std::size_t r = std::size_t(j) * f.shadowSamples + k;
        visible += shadowTraced[r] && !shadowOccluded[r] ? 1u : 0u;
      }
      visibility = float(visible) / float(f.shadowSamples);
    }
    const Vec3 meshAlbedo{0.78f, 0.60f, 0.44f};
    const Vec3 sun{1.00f, 0.94f, 0.84f};
    Vec3 albedo = meshAlbedo;
    Vec3 shading = s.normal;
    float fade = 0.0f;
    if (s.kind == kMesh) {
      const uint32_t* t3 = indices + 3 * std::size_t(s.tri);
      const Vec3 smooth = normalizeExact(loadVertex(normals, t3[0]) * (1.0f - s.u - s.v) +
                                         loadVertex(normals, t3[1]) * s.u + loadVertex(normals, t3[2]) * s.v);
      shading = dot(smooth, s.normal) < 0.0f ? smooth * -1.0f : smooth;
    }
    if (s.kind == kGround) {
      Vec3 t, b;
      orthonormalBasis(up, t, b);
      const Vec3 rel = s.position - f.light.sceneCenter;
      const auto cu = int32_t(floorf(dot(rel, t) / f.light.groundScale));
      const auto cv = int32_t(floorf(dot(rel, b) / f.light.groundScale));
      albedo = ((cu + cv) & 1) ? Vec3{0.62f, 0.60f, 0.56f} : Vec3{0.50f, 0.49f, 0.46f};
      const float d = sqrtf(dot(rel, rel)) / (6.0f * f.light.sceneRadius);
      fade = 1.0f - expf(-d * d);
    }
    const Vec3 toLight = normalizeExact(f.light.lightCenter - s.position);
    const float diffuse = fmaxf(0.0f, dot(shading, toLight)) * visibility;
    const Vec3 sky = skyColor(normalizeExact(shading + up * 0.5f), up) * 0.6f;
    const Vec3 lit = sky * ao + sun * diffuse;
    color = mul(albedo, lit);
    if (fade > 0.0f) color = mix(color, Vec3{0.80f, 0.85f, 0.91f}, fade);  // into the horizon
  }
  uint8_t* px = image + 3 * std::size_t(pixelIndex(f, x, y));
  px[0] = toSrgb8(color.x);
  px[1] = toSrgb8(color.y);
  px[2] = toSrgb8(color.z);
}

}  // namespace

RenderStats renderFrameGpu(GpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                           const RenderSettings& settings, Image* image, GpuRenderTimings* timings) {
  if (settings.width == 0 || settings.height == 0) throw anim::Error("render: the image size must be positive");
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
    throw anim::Error("render: too many rays for one frame");
  f.padded = uint32_t(padded);
  f.cam = cameraRays(camera, f.width, f.height);
  f.light = lighting;
  f.aoSamples = settings.aoSamples;
  f.shadowSamples = settings.shadowSamples;
  f.base = {settings.seed, settings.frame, 0};

  m.rays.reserve(std::max<uint64_t>(padded, aoRays));
  m.hits.reserve(padded);
  m.surfaces.reserve(3 * padded);
  m.occluded.reserve(std::max<uint64_t>(aoRays, 1));
  m.shadowRays.reserve(std::max<uint64_t>(shadowRays, 1));
  m.shadowOccluded.reserve(std::max<uint64_t>(2 * shadowRays, 2));  // results, then "traced" flags
  m.image.reserve(std::size_t(f.width) * f.height * 3);
  uint8_t* shadowTraced = m.shadowOccluded.data() + shadowRays;

  const detail::TraceScene scene = m.scene();
  const detail::TraceLaunch launch = m.traceLaunch();
  const unsigned block = 256;
  cudaStream_t stream = m.stream;
  auto& ev = m.events;

  m.words.fillBytes(0, stream);
  ev.record(0, stream);
  primaryRaysKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.rays.data());
  CUDA_CHECK_LAUNCH("primaryRaysKernel");
  ev.record(1, stream);
  detail::launchTrace(scene, m.rays.data(), f.padded, m.hits.data(), nullptr, m.words.data() + kPrimaryCounter, launch,
                      stream);
  ev.record(2, stream);
  surfaceKernel<<<detail::gridFor(padded, block), block, 0, stream>>>(f, m.hits.data(), m.indices.data(),
                                                                      m.positions.data(), m.surfaces.data());
  CUDA_CHECK_LAUNCH("surfaceKernel");
  if (aoRays > 0) {
    aoRaysKernel<<<detail::gridFor(aoRays, block), block, 0, stream>>>(f, m.surfaces.data(), m.rays.data(),
                                                                       m.words.data());
    CUDA_CHECK_LAUNCH("aoRaysKernel");
  }
  ev.record(3, stream);
  detail::launchTrace(scene, m.rays.data(), uint32_t(aoRays), nullptr, m.occluded.data(), m.words.data() + kAoCounter,
                      launch, stream);
  ev.record(4, stream);
  if (shadowRays > 0) {
    shadowRaysKernel<<<detail::gridFor(shadowRays, block), block, 0, stream>>>(f, m.surfaces.data(),
                                                                               m.shadowRays.data(), shadowTraced,
                                                                               m.words.data());
    CUDA_CHECK_LAUNCH("shadowRaysKernel");
  }
  ev.record(5, stream);
  detail::launchTrace(scene, m.shadowRays.data(), uint32_t(shadowRays), nullptr, m.shadowOccluded.data(),
                      m.words.data() + kShadowCounter, launch, stream);
  ev.record(6, stream);
  if (m.vertexTris.empty()) m.buildVertexTriangles();
  vertexNormalsKernel<<<detail::gridFor(m.vertices, block), block, 0, stream>>>(
      m.vertices, m.vertexTriOffsets.data(), m.vertexTris.data(), m.indices.data(), m.positions.data(),
      m.normals.data());
  CUDA_CHECK_LAUNCH("vertexNormalsKernel");
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
  stats.shadeMs = ev.ms(6, 7);
  if (timings) {
    timings->generateMs = ev.ms(0, 1) + ev.ms(2, 3) + ev.ms(4, 5);
    timings->shadeMs = stats.shadeMs;
    timings->downloadMs = ev.ms(7, 8);
    timings->totalMs = ev.ms(0, 8);
  }
  return stats;
}

}  // namespace tsah::cuda
