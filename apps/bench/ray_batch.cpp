#include "bench/ray_batch.hpp"

#include <atomic>
#include <chrono>

#include "tsah/render/sampling.hpp"
#include "tsah/render/shading.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::bench {

RayBatch makeRayBatch(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                      const RenderSettings& settings) {
  const uint32_t width = settings.width, height = settings.height;
  const std::size_t pixels = std::size_t(width) * height;
  const CameraRays cam = cameraRays(camera, width, height);
  RayBatch batch;
  batch.primary.resize(pixels);
  std::vector<Surface> surfaces(pixels);
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        batch.primary[i] = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
        surfaces[i] = primarySurface(batch.primary[i], runtime.closestHit(batch.primary[i]), runtime.indices().data(),
                                     runtime.positions().data(), lighting);
      }
  });
  // Secondary rays in pixel order: AO rays at fixed offsets, shadow rays gathered per row.
  std::vector<std::size_t> aoFirst(pixels + 1, 0);
  for (std::size_t i = 0; i < pixels; ++i)
    aoFirst[i + 1] = aoFirst[i] + (surfaces[i].kind == SurfaceKind::None ? 0 : settings.aoSamples);
  batch.ao.resize(aoFirst[pixels]);
  std::vector<std::vector<Ray>> shadowRows(height);
  const SampleKey base{settings.seed, settings.frame, 0};
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        const Surface& s = surfaces[i];
        if (s.kind == SurfaceKind::None) continue;
        SampleKey key = base;
        key.pixel = uint32_t(i);
        for (uint32_t k = 0; k < settings.aoSamples; ++k) batch.ao[aoFirst[i] + k] = aoRay(s, key, k, lighting.aoDistance);
        for (uint32_t k = 0; k < settings.shadowSamples; ++k) {
          Ray ray;
          if (shadowRay(s, lighting, key, k, ray)) shadowRows[y].push_back(ray);
        }
      }
  });
  for (const auto& row : shadowRows) batch.shadow.insert(batch.shadow.end(), row.begin(), row.end());
  return batch;
}

namespace {

template <typename Trace>
RayPassStats timedPass(const CpuRuntime& runtime, const std::vector<Ray>& rays, uint64_t& resultCount, Trace trace) {
  constexpr std::size_t kChunk = 4096;  // rays per task: enough work per task, enough tasks per thread
  std::atomic<uint64_t> count{0};
  const auto start = std::chrono::steady_clock::now();
  const std::size_t chunks = (rays.size() + kChunk - 1) / kChunk;
  runtime.parallelFor(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    uint64_t local = 0;
    for (std::size_t c = c0; c < c1; ++c) {
      const std::size_t first = c * kChunk;
      trace(rays, first, std::min(kChunk, rays.size() - first), local);
    }
    count += local;
  });
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  resultCount = count.load();
  return {rays.size(), ms};
}

}  // namespace

BatchTrace traceBatch(const CpuRuntime& runtime, const RayBatch& batch, const BatchTracer& tracer) {
  BatchTrace t;
  t.primary = timedPass(runtime, batch.primary, t.primaryHits, tracer.closest);
  // The renderer's any-hit orders (renderer.cpp): tree order for the short AO rays, farthest
  // first for the shadow rays.
  auto occluded = [&tracer](AnyHitOrder order) {
    return [&tracer, order](const std::vector<Ray>& rays, std::size_t first, std::size_t count, uint64_t& n) {
      tracer.occluded(rays, first, count, order, n);
    };
  };
  t.ao = timedPass(runtime, batch.ao, t.aoOccluded, occluded(AnyHitOrder::TreeOrder));
  t.shadow = timedPass(runtime, batch.shadow, t.shadowOccluded, occluded(AnyHitOrder::FarthestFirst));
  return t;
}

BatchTracer toolkitTracer(const CpuRuntime& runtime) {
  BatchTracer tracer;
  tracer.closest = [&runtime](const std::vector<Ray>& rays, std::size_t first, std::size_t count, uint64_t& hits) {
    for (std::size_t i = first; i < first + count; ++i) hits += runtime.closestHit(rays[i]).valid() ? 1u : 0u;
  };
  tracer.occluded = [&runtime](const std::vector<Ray>& rays, std::size_t first, std::size_t count, AnyHitOrder order,
                               uint64_t& occluded) {
    for (std::size_t i = first; i < first + count; ++i) occluded += runtime.anyHit(rays[i], order) ? 1u : 0u;
  };
  return tracer;
}

}  // namespace tsah::bench
