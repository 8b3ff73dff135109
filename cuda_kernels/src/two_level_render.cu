// The two-level renderer's device side (two_level_render.hpp): the renderer's fused passes
// (render_passes.cuh) with a tracer through the two-level scene (two_level_traversal.cuh; a blurred
// frame: two_level_blur_traversal.cuh at each pixel's shutter time), and the surfaces and smooth
// normals of the hit instance's triangles moved into the world.
// Compiled with -fmad=false (CMakeLists.txt): surfaces and colours round as on the CPU.
#include "two_level_render.hpp"

#include "two_level_blur_traversal.cuh"
#include "two_level_traversal.cuh"

namespace tsah::cuda::detail {

namespace {

// The tables with the device lookups of the tracer and the shading.
struct ShadingTables : TwoLevelShadingTables {
  // The instance holding bake-order triangle `tri`: the last one whose first triangle is at most
  // tri (an instance of an empty source shares its first triangle with the next one).
  __device__ __forceinline__ uint32_t instanceOf(uint32_t tri) const {
    uint32_t lo = 0, hi = instanceCount;  // firstTriangle[lo] <= tri < firstTriangle[hi]
    while (hi - lo > 1) {
      const uint32_t mid = lo + (hi - lo) / 2;
      if (firstTriangle[mid] <= tri)
        lo = mid;
      else
        hi = mid;
    }
    return lo;
  }

  // Triangle `prim` of the instance's source in the world, 9 floats: the pose's positions moved by
  // world(t) in double, rounded to float (anim::transformPoints, as the baked scene's vertices).
  __device__ __forceinline__ void worldTriangle(const InstanceState& inst, const BlasView& view, uint32_t prim,
                                                float* out) const {
    for (int k = 0; k < 3; ++k) {
      const Vec3 p = transformPointRows(inst.world, loadVec3(view.positions, view.indices[3 * std::size_t(prim) + k]));
      out[3 * k] = p.x;
      out[3 * k + 1] = p.y;
      out[3 * k + 2] = p.z;
    }
  }
};

// Form: the runtime's BLAS layout (each tracer's passes are compiled once per layout).
template <BlasForm Form>
struct TwoLevelTracer {
  static constexpr bool kTimed = false, kOwnSurface = true;
  ShadingTables tables;

  __device__ __forceinline__ bool anyHit(const Ray& ray, float) const {
    return twoLevelAnyHit<Form>(tables.scene, ray);
  }

  // tsah::primarySurface on the hit triangle in the world: the normal is the cross product of its
  // world-space edges, as the CPU renderer computes it from its world mesh (so the surfaces are
  // equal bit for bit, mirrored instances included; a normal by the inverse transpose of world(t)
  // would round differently).
  __device__ __forceinline__ Surface surface(const Ray& ray, float, const SceneLighting& light) const {
    const InstanceHit h = twoLevelClosestHit<Form>(tables.scene, ray);
    if (h.instance == kNoHit) return primarySurface(ray, Hit{}, nullptr, nullptr, light);
    const InstanceState& inst = tables.scene.instances[h.instance];
    float triangle[9];
    tables.worldTriangle(inst, tables.scene.views[inst.view], h.prim, triangle);
    Hit local;
    local.t = h.t;
    local.u = h.u;
    local.v = h.v;
    local.tri = 0;
    const uint32_t oneTriangle[3] = {0, 1, 2};
    Surface s = primarySurface(ray, local, oneTriangle, triangle, light);
    if (s.kind == SurfaceKind::Mesh) s.tri = tables.firstTriangle[h.instance] + h.prim;
    return s;
  }
};

// A blurred frame: each ray at its pixel's shutter time through the blurred TLAS and BLAS. The
// primary surface is on the hit triangle where it is at that time: its pose's key positions lerped
// (a moving pose; else its instant positions) and moved into the world by the instance's key
// matrices lerped, as tsah::TwoLevelRenderView::blurredSurface computes it.
template <BlasForm Form>
struct BlurredTwoLevelTracer {
  static constexpr bool kTimed = true, kOwnSurface = true;
  ShadingTables tables;
  BlurredTlasScene blur;

  __device__ __forceinline__ bool anyHit(const Ray& ray, float time) const {
    return blurredTwoLevelAnyHit<Form>(blur, ray, time);
  }

  __device__ __forceinline__ Surface surface(const Ray& ray, float time, const SceneLighting& light) const {
    const InstanceHit h = blurredTwoLevelClosestHit<Form>(blur, ray, time);
    if (h.instance == kNoHit) return primarySurface(ray, Hit{}, nullptr, nullptr, light);
    const motion::Segment seg = motion::segmentAt(blur.keyTimes, int(blur.keyCount), time);
    const std::size_t key = std::size_t(seg.index) * blur.instanceCount + h.instance;
    const Affine3x4 toWorld =
        motion::lerpAffine(blur.keyToWorld[key], blur.keyToWorld[key + blur.instanceCount], seg.f);
    const BlasView& view = blur.views[blur.instances[h.instance].view];
    const float* p0 = view.positions;
    const float* p1 = p0;
    float f = 0.0f;
    const uint32_t layout = blur.blurred[h.instance].layout;
    if (layout != kInvalidIndex) {
      const BlurredPosePositions keys = blur.posePositions[layout];
      p0 = keys.keys + std::size_t(seg.index) * keys.keyStride;
      p1 = p0 + keys.keyStride;
      f = seg.f;
    }
    float triangle[9];
    for (int k = 0; k < 3; ++k) {
      const uint32_t vertex = view.indices[3 * std::size_t(h.prim) + k];
      const Vec3 v = toWorld.point(motion::lerpVertex(loadVec3(p0, vertex), loadVec3(p1, vertex), f));
      triangle[3 * k] = v.x;
      triangle[3 * k + 1] = v.y;
      triangle[3 * k + 2] = v.z;
    }
    return primarySurfaceOnTriangle(ray, Hit{h.t, h.u, h.v, tables.firstTriangle[h.instance] + h.prim}, triangle,
                                    light);
  }
};

struct TwoLevelShading {
  ShadingTables tables;

  // The smooth normal of a vertex of the instance: the sum of the world-space face normals of its
  // triangles in increasing order, as the CPU renderer sums them over its world mesh.
  __device__ __forceinline__ Vec3 vertexNormal(const InstanceState& inst, const BlasView& view, const uint32_t* offsets,
                                               uint32_t vertex) const {
    const uint32_t oneTriangle[3] = {0, 1, 2};
    Vec3 n{0, 0, 0};
    for (uint32_t e = offsets[vertex]; e < offsets[vertex + 1]; ++e) {
      float triangle[9];
      tables.worldTriangle(inst, view, tables.vertexTris[e], triangle);
      n = n + faceNormal(oneTriangle, triangle, 0);
    }
    return n;
  }

  __device__ __forceinline__ Vec3 color(const Surface& s, const Ray& cameraRay, float ao, float visibility,
                                        const SceneLighting& light) const {
    if (s.kind != SurfaceKind::Mesh) return pixelColor(s, cameraRay, ao, visibility, nullptr, nullptr, light);
    const uint32_t instance = tables.instanceOf(s.tri);
    const uint32_t prim = s.tri - tables.firstTriangle[instance];
    const InstanceState& inst = tables.scene.instances[instance];
    const BlasView& view = tables.scene.views[inst.view];
    const uint32_t* offsets = tables.vertexTriOffsets + tables.sourceOffsets[instance];
    float normals[9];
    for (int k = 0; k < 3; ++k) {
      const Vec3 n = vertexNormal(inst, view, offsets, view.indices[3 * std::size_t(prim) + k]);
      normals[3 * k] = n.x;
      normals[3 * k + 1] = n.y;
      normals[3 * k + 2] = n.z;
    }
    Surface local = s;
    local.tri = 0;
    const uint32_t oneTriangle[3] = {0, 1, 2};
    return pixelColor(local, cameraRay, ao, visibility, oneTriangle, normals, light);
  }
};

// The fused passes' surfaces of the image's pixels, row-major.
__global__ void unpackSurfacesKernel(Frame f, const float4* __restrict__ surfaces, Surface* __restrict__ out) {
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= f.padded) return;
  uint32_t x, y;
  if (pixelOf(f, j, x, y)) out[pixelIndex(f, x, y)] = loadSurface(surfaces, j);
}

}  // namespace

RenderStats renderTwoLevelFrame(const PassBuffers& b, const Frame& f, const TwoLevelShadingTables& tables,
                                const BlurredTlasScene* blurred, uint64_t aoRays, uint64_t shadowRays, Image* image,
                                GpuRenderTimings* timings) {
  const ShadingTables t{tables};
  const auto passes = [&](auto tracer) {
    enqueueFusedPasses(b, f, tracer, nullptr, nullptr, aoRays, shadowRays, [](cudaStream_t) {});
  };
  constexpr BlasForm kBinary = BlasForm::Binary, kCompressed = BlasForm::Compressed;
  const bool compressed = tables.scene.compressedBlas;
  if (blurred && compressed)
    passes(BlurredTwoLevelTracer<kCompressed>{t, *blurred});
  else if (blurred)
    passes(BlurredTwoLevelTracer<kBinary>{t, *blurred});
  else if (compressed)
    passes(TwoLevelTracer<kCompressed>{t});
  else
    passes(TwoLevelTracer<kBinary>{t});
  return shadeAndFinish(b, f, TwoLevelShading{t}, true, image, timings);
}

void launchUnpackSurfaces(const Frame& f, const float4* surfaces, Surface* out, cudaStream_t stream) {
  const unsigned block = 256;
  unpackSurfacesKernel<<<gridFor(f.padded, block), block, 0, stream>>>(f, surfaces, out);
  CUDA_CHECK_LAUNCH("unpackSurfacesKernel");
}

}  // namespace tsah::cuda::detail
