// The GPU side of the runtime benchmark: the per-frame driver (frame_runtime.hpp) on the GPU runtime,
// one method at a time.
#include "bench/runtime_bench.hpp"
#include "frame_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah::bench {

namespace {

// The frames of one method, each updated and rendered by the driver.
RuntimeMethod runFrames(cli::FrameRuntime& runtime, const RuntimeSetup& setup, RuntimeMethod method, Image* image,
                        uint32_t imageFrame, double* convertMs) {
  RenderSettings settings = setup.settings;
  runtime.warmUp(setup.times.front(), setup.camera, setup.lighting, settings);
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    reportFrame(setup, method.label, f);
    settings.frame = static_cast<uint32_t>(f);
    const cli::FrameUpdate u = runtime.update(setup.times[f]);
    if (convertMs) *convertMs += u.convertMs;
    method.frames.push_back(timeFrame(runtime, setup, setup.times[f], u.updateMs, settings,
                                      image && f == imageFrame ? image : nullptr));
  }
  return method;
}

// The layout the method was traced in (--layout auto: the runtime's default).
void describeLayout(const cli::FrameRuntime& runtime, RuntimeMethod& m) {
  nlohmann::json description;
  runtime.describe(description);
  m.extra["layout"] = description["layout"];
}

cli::FrameRuntimeOptions gpuOptions(const std::string& layout, const Objective& objective, int gpu) {
  cli::FrameRuntimeOptions options;
  options.device = Device::Cuda;
  options.gpu = gpu;
  options.layout = layout.empty() ? Layout::Auto : parse<Layout>(layout);
  options.objective = objective;
  return options;
}

}  // namespace

RuntimeMethod runGpuRefit(const anim::Animation& a, const RefitTrees& trees, const RuntimeSetup& setup, Image* image,
                          uint32_t imageFrame, const std::string& layout) {
  // One runtime with every tree uploaded once; each update refits the tree of the frame's part.
  const auto runtime = cli::makeFrameRuntime(treeSetOf(trees, a), a, gpuOptions(layout, setup.collapse, setup.gpu));
  RuntimeMethod m = runFrames(*runtime, setup, {trees.name, trees.label, "refit", {}, nlohmann::json::object()}, image,
                              imageFrame, nullptr);
  describeLayout(*runtime, m);
  return m;
}

RuntimeMethod runGpuRebuild(const anim::Animation& a, const Bvh& initialTree, const std::string& method,
                            const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup,
                            const std::string& layout) {
  cli::FrameRuntimeOptions options = gpuOptions(layout, Objective{0, cost, maxLeaf}, setup.gpu);
  options.rebuild = cli::parseRebuild(method);
  TreeSet first;
  first.trees.push_back(flattenBvh(initialTree));
  first.ranges = {{a.startTime(), a.endTime()}};
  const auto runtime = cli::makeFrameRuntime(first, a, options);
  const std::string label = options.rebuild == cli::Rebuild::Lbvh ? "LBVH rebuild (HLBVH-med)" : "HLBVH-SAH rebuild";
  double convertMs = 0.0;
  RuntimeMethod m = runFrames(*runtime, setup, {method, label, "rebuild", {}, nlohmann::json::object()}, nullptr, 0,
                              &convertMs);
  describeLayout(*runtime, m);
  if (m.extra["layout"] == "cwbvh")
    m.extra["wide_conversion_ms"] = setup.times.empty() ? 0.0 : convertMs / double(setup.times.size());
  return m;
}

}  // namespace tsah::bench
