#include "bench/ray_batch.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

#include "tsah/base/error.hpp"
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
  const SampleKey base{settings.seed, settings.frame, 0};
  // A blurred frame: every ray of a pixel at the pixel's shutter time, as renderFrame traces it.
  const bool blurred = runtime.blurred();
  if (blurred) {
    batch.times.primary.resize(pixels);
    for (std::size_t i = 0; i < pixels; ++i) {
      SampleKey key = base;
      key.pixel = uint32_t(i);
      batch.times.primary[i] = pixelShutterTime(key);
    }
  }
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        batch.primary[i] = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
        const float time = blurred ? batch.times.primary[i] : 0.0f;
        surfaces[i] = blurred ? blurredPrimarySurface(batch.primary[i], runtime.closestHit(batch.primary[i], time),
                                                      runtime.motionView(), time, lighting)
                              : primarySurface(batch.primary[i], runtime.closestHit(batch.primary[i]),
                                               runtime.indices().data(), runtime.positions().data(), lighting);
      }
  });
  // Secondary rays in pixel order: AO rays at fixed offsets, shadow rays gathered per row.
  std::vector<std::size_t> aoFirst(pixels + 1, 0);
  for (std::size_t i = 0; i < pixels; ++i)
    aoFirst[i + 1] = aoFirst[i] + (surfaces[i].kind == SurfaceKind::None ? 0 : settings.aoSamples);
  batch.ao.resize(aoFirst[pixels]);
  if (blurred) batch.times.ao.resize(aoFirst[pixels]);
  std::vector<std::vector<Ray>> shadowRows(height);
  std::vector<std::vector<float>> shadowTimeRows(height);
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        const Surface& s = surfaces[i];
        if (s.kind == SurfaceKind::None) continue;
        SampleKey key = base;
        key.pixel = uint32_t(i);
        for (uint32_t k = 0; k < settings.aoSamples; ++k) {
          batch.ao[aoFirst[i] + k] = aoRay(s, key, k, lighting.aoDistance);
          if (blurred) batch.times.ao[aoFirst[i] + k] = batch.times.primary[i];
        }
        for (uint32_t k = 0; k < settings.shadowSamples; ++k) {
          Ray ray;
          if (!shadowRay(s, lighting, key, k, ray)) continue;
          shadowRows[y].push_back(ray);
          if (blurred) shadowTimeRows[y].push_back(batch.times.primary[i]);
        }
      }
  });
  for (const auto& row : shadowRows) batch.shadow.insert(batch.shadow.end(), row.begin(), row.end());
  for (const auto& row : shadowTimeRows) batch.times.shadow.insert(batch.times.shadow.end(), row.begin(), row.end());
  return batch;
}

RayTimes mapTimes(const RayTimes& times, const std::function<float(float)>& f) {
  RayTimes out = times;
  for (std::vector<float>* pass : {&out.primary, &out.ao, &out.shadow})
    for (float& t : *pass) t = f(t);
  return out;
}

std::size_t raysPerTask(std::size_t rays) {
  // A frame's shadow pass can hold about 20,000 rays, which in tasks of 4096 ran on 6 threads of 16.
  constexpr std::size_t kMaxChunk = 4096, kMinChunk = 64, kMinTasks = 128;
  return std::clamp((rays + kMinTasks - 1) / kMinTasks, kMinChunk, kMaxChunk);
}

namespace {

// Traces rays [first, first + count) per task with trace(rays, times, count, results); times and
// results are parallel to the rays (times empty: the instant).
template <typename Result, typename Trace>
RayPassStats timedPass(const Workers& workers, const std::vector<Ray>& rays, const std::vector<float>& times,
                       std::vector<Result>& results, Trace trace) {
  const std::size_t chunk = raysPerTask(rays.size());
  results.assign(rays.size(), Result{});
  const auto start = std::chrono::steady_clock::now();
  const std::size_t chunks = (rays.size() + chunk - 1) / chunk;
  workers.parallelFor(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      const std::size_t first = c * chunk;
      trace(rays.data() + first, times.empty() ? nullptr : times.data() + first, std::min(chunk, rays.size() - first),
            results.data() + first);
    }
  });
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return {rays.size(), ms};
}

uint64_t countSet(const std::vector<uint8_t>& flags) {
  uint64_t n = 0;
  for (uint8_t f : flags) n += f ? 1u : 0u;
  return n;
}

}  // namespace

bool startWorkers(const Workers& workers, std::chrono::milliseconds wait) {
  // Each thread counts itself once per call (its first task of this generation); every task then
  // waits for the others, so no thread runs two and all of them are up when it returns.
  static std::atomic<uint64_t> generations{0};
  const uint64_t generation = ++generations;
  std::atomic<uint32_t> started{0};
  const auto deadline = std::chrono::steady_clock::now() + wait;
  workers.parallelFor(std::size_t(workers.threads) * 4, 1, [&](std::size_t, std::size_t) {
    thread_local uint64_t joined = 0;
    if (joined != generation) {
      joined = generation;
      started.fetch_add(1, std::memory_order_relaxed);
    }
    while (started.load(std::memory_order_relaxed) < workers.threads && std::chrono::steady_clock::now() < deadline)
      std::this_thread::yield();
  });
  return started.load() >= workers.threads;
}

bool startWorkers(const CpuRuntime& runtime) { return startWorkers(workersOf(runtime)); }

BatchTrace traceBatch(const CpuRuntime& runtime, const RayBatch& batch, const BatchTracer& tracer,
                      const RayTimes* times) {
  return traceBatch(workersOf(runtime), batch, tracer, times);
}

BatchTrace traceBatch(const Workers& workers, const RayBatch& batch, const BatchTracer& tracer,
                      const RayTimes* times) {
  const RayTimes& at = times ? *times : batch.times;
  if (!at.empty() && (at.primary.size() != batch.primary.size() || at.ao.size() != batch.ao.size() ||
                      at.shadow.size() != batch.shadow.size()))
    throw tsah::ConfigError("bench: the ray times do not match the batch's rays");
  BatchTrace t;
  t.primary = timedPass(workers, batch.primary, at.primary, t.closest, tracer.closest);
  // The renderer's any-hit orders (renderer.cpp): tree order for the short AO rays, farthest
  // first for the shadow rays.
  auto occluded = [&tracer](AnyHitOrder order) {
    return [&tracer, order](const Ray* rays, const float* rayTimes, std::size_t count, uint8_t* out) {
      tracer.occluded(rays, rayTimes, count, order, out);
    };
  };
  t.ao = timedPass(workers, batch.ao, at.ao, t.aoResults, occluded(AnyHitOrder::TreeOrder));
  t.shadow = timedPass(workers, batch.shadow, at.shadow, t.shadowResults, occluded(AnyHitOrder::FarthestFirst));
  for (const Hit& h : t.closest) t.primaryHits += h.valid() ? 1u : 0u;
  t.aoOccluded = countSet(t.aoResults);
  t.shadowOccluded = countSet(t.shadowResults);
  return t;
}

BatchTracer toolkitTracer(const CpuRuntime& runtime) {
  BatchTracer tracer;
  tracer.closest = [&runtime](const Ray* rays, const float* times, std::size_t count, Hit* hits) {
    if (times)
      for (std::size_t i = 0; i < count; ++i) hits[i] = runtime.closestHit(rays[i], times[i]);
    else
      for (std::size_t i = 0; i < count; ++i) hits[i] = runtime.closestHit(rays[i]);
  };
  tracer.occluded = [&runtime](const Ray* rays, const float* times, std::size_t count, AnyHitOrder order,
                               uint8_t* occluded) {
    if (times)
      for (std::size_t i = 0; i < count; ++i) occluded[i] = runtime.anyHit(rays[i], times[i], order) ? 1 : 0;
    else
      for (std::size_t i = 0; i < count; ++i) occluded[i] = runtime.anyHit(rays[i], order) ? 1 : 0;
  };
  return tracer;
}

}  // namespace tsah::bench
