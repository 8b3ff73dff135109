// The GPU side of the runtime benchmark: GpuRuntime + renderFrameGpu per method (built with CUDA).
#include <algorithm>
#include <memory>

#include "tsah/base/error.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/layout/flat_bvh.hpp"

#if TSAH_HAVE_CUDA
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace tsah::bench {

#if TSAH_HAVE_CUDA

namespace {

void report(const RuntimeSetup& setup, const std::string& label, std::size_t frame) {
  if (setup.progress && (frame == 0 || (frame + 1) % 10 == 0 || frame + 1 == setup.times.size()))
    setup.progress(label + ": frame " + std::to_string(frame + 1) + "/" + std::to_string(setup.times.size()));
}

void requireDevice() {
  if (!cuda::deviceAvailable()) throw tsah::Failure("--device cuda: no CUDA device is available on this machine");
}

// Renders the current frame: the ray passes (device time of the traversal kernels) and the whole
// frame on the device; the image is downloaded only when asked for, in a separate untimed render.
void renderTimed(cuda::GpuRuntime& gpu, const RuntimeSetup& setup, double t, const RenderSettings& settings,
                 FrameTiming& ft, Image* image) {
  cuda::GpuRenderTimings timings;
  ft.rays = cuda::renderFrameGpu(gpu, setup.camera(t), setup.lighting, settings, nullptr, &timings);
  ft.traceMs = ft.rays.total().ms;
  ft.totalMs = ft.updateMs + timings.totalMs;
  if (image) cuda::renderFrameGpu(gpu, setup.camera(t), setup.lighting, settings, image, nullptr);
}

}  // namespace

bool gpuAvailable() { return cuda::deviceAvailable(); }

nlohmann::json gpuJson() {
  if (!cuda::deviceAvailable()) return nullptr;
  const cuda::DeviceInfo d = cuda::describeDevice(0);
  return {{"name", d.name},
          {"compute_capability", std::to_string(d.computeMajor) + "." + std::to_string(d.computeMinor)},
          {"multiprocessors", d.multiprocessors},
          {"memory_mib", double(d.globalMemoryBytes) / (1024.0 * 1024.0)},
          {"driver_version", d.driverVersion},
          {"runtime_version", d.runtimeVersion}};
}

RuntimeMethod runGpuRefit(const anim::Animation& a, const RefitTrees& trees, const RuntimeSetup& setup, Image* image,
                          uint32_t imageFrame, const std::string& layout) {
  requireDevice();
  cuda::GpuRuntime::Config config;
  if (!layout.empty()) config.layout = cuda::parseTreeLayout(layout);
  // One runtime with every tree uploaded once; updateAt refits the tree of the frame's part.
  const TreeSet set = treeSetOf(trees, a);
  cuda::GpuRuntime gpu(set, a, config);
  RenderSettings settings = setup.settings;
  // Warm-up (untimed): the first update of each tree captures its CUDA graph, the first render the
  // renderer's; a time inside each tree's part reaches every tree.
  for (uint32_t s = 0; s < set.size(); ++s) {
    const double t = s == 0 ? setup.times.front() : switchTime(set.ranges, s - 1);
    gpu.updateAt(t);
    cuda::renderFrameGpu(gpu, setup.camera(t), setup.lighting, settings, nullptr, nullptr);
  }
  RuntimeMethod m{trees.name, trees.label, "refit", {}, nlohmann::json::object()};
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    report(setup, trees.label, f);
    const double t = setup.times[f];
    FrameTiming ft;
    ft.time = t;
    ft.updateMs = gpu.updateAt(t).totalMs();
    settings.frame = static_cast<uint32_t>(f);
    renderTimed(gpu, setup, t, settings, ft, image && f == imageFrame ? image : nullptr);
    m.frames.push_back(ft);
  }
  return m;
}

RuntimeMethod runGpuRebuild(const anim::Animation& a, const Bvh& initialTree, const std::string& method,
                            const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup,
                            const std::string& layout) {
  requireDevice();
  cuda::GpuRuntime::Config config;
  if (!layout.empty()) config.layout = cuda::parseTreeLayout(layout);
  const bool wide = config.layout == cuda::TreeLayout::Cwbvh;
  cuda::RebuildOptions options;
  options.method = cuda::parseRebuildMethod(method);
  options.collapse = true;
  // The compressed layout holds leaves of at most 8 triangles (64 per node).
  options.maxLeafSize = wide ? std::min(maxLeaf, kCwbvhMaxLeafTriangles) : maxLeaf;
  options.cost = cost;
  cuda::GpuRuntime gpu(flattenBvh(initialTree), a, config);
  RenderSettings settings = setup.settings;
  gpu.rebuildAt(setup.times.front(), options);  // warm-up: captures the rebuild's graph
  cuda::renderFrameGpu(gpu, setup.camera(setup.times.front()), setup.lighting, settings, nullptr, nullptr);
  RuntimeMethod m;
  m.name = method;
  m.label = options.method == cuda::RebuildMethod::Lbvh ? "LBVH rebuild (HLBVH-med)" : "HLBVH-SAH rebuild";
  m.update = "rebuild";
  double wideMs = 0.0;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    report(setup, m.label, f);
    const double t = setup.times[f];
    FrameTiming ft;
    ft.time = t;
    const cuda::RebuildTimings r = gpu.rebuildAt(t, options);
    ft.updateMs = r.totalMs();  // with the conversion to the compressed layout (cwbvh)
    wideMs += r.wideMs;
    settings.frame = static_cast<uint32_t>(f);
    renderTimed(gpu, setup, t, settings, ft, nullptr);
    m.frames.push_back(ft);
  }
  m.extra["layout"] = cuda::treeLayoutName(gpu.config().layout);
  if (wide) m.extra["wide_conversion_ms"] = setup.times.empty() ? 0.0 : wideMs / double(setup.times.size());
  return m;
}

#else  // no CUDA

bool gpuAvailable() { return false; }
nlohmann::json gpuJson() { return nullptr; }

RuntimeMethod runGpuRefit(const anim::Animation&, const RefitTrees&, const RuntimeSetup&, Image*, uint32_t,
                          const std::string&) {
  throw tsah::ConfigError("--device cuda: this tsah was built without the CUDA runtime");
}
RuntimeMethod runGpuRebuild(const anim::Animation&, const Bvh&, const std::string&, const CostModel&, uint32_t,
                            const RuntimeSetup&, const std::string&) {
  throw tsah::ConfigError("--device cuda: this tsah was built without the CUDA runtime");
}

#endif

}  // namespace tsah::bench
