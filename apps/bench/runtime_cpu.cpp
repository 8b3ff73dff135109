// The CPU side of the runtime benchmark: CpuRuntime + renderFrame per method, and the Embree peer.
#include <array>
#include <chrono>
#include <memory>

#include "bench/embree_peer.hpp"
#include "bench/runtime_bench.hpp"
#include "frame_runtime.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah::bench {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The bench's frames come from the animation, whose static vertices stay at rest: the runtime
// refits what moves (CpuRuntime::Config::movingVertices).
CpuRuntime::Config runtimeConfig(const anim::Animation& a, const RuntimeSetup& setup, Layout layout) {
  CpuRuntime::Config c(setup.threads);
  c.layout = layout;
  c.collapse = setup.collapse;
  if (!a.allMoving()) c.movingVertices.emplace(a.movingVertices().begin(), a.movingVertices().end());
  return c;
}

// A tree set's runtime (each frame selects the tree of its part).
std::unique_ptr<CpuRuntime> makeSetRuntime(const anim::Animation& a, const RefitTrees& trees, const RuntimeSetup& setup) {
  return std::make_unique<CpuRuntime>(treeSetOf(trees, a), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                      a.vertexCount(), runtimeConfig(a, setup, setup.layout));
}

// "LABEL, bvh8, avx512": the layout and, for a wide one, its kernels.
std::string layoutLabel(const std::string& label, const CpuRuntime& rt) {
  const LayoutInfo& l = rt.layoutInfo();
  return label + ", " + tsah::name(l.layout) + (l.layout == Layout::Bvh2 ? "" : std::string(", ") + name(l.isa));
}

// The toolkit's layouts for the Embree comparison: the default (fastest) one first.
std::vector<Layout> comparedLayouts(Layout first) {
  std::vector<Layout> out{first};
  for (Layout l : {Layout::Bvh8, Layout::Bvh4, Layout::Bvh2})
    if (l != first && layoutSupported(l)) out.push_back(l);
  return out;
}

nlohmann::json layoutJson(const CpuRuntime& rt) {
  const LayoutInfo& l = rt.layoutInfo();
  nlohmann::json j = {{"layout", tsah::name(l.layout)},
                      {"interior_nodes", l.interiorNodes},
                      {"leaves", l.leaves},
                      {"depth", l.depth},
                      {"tsah_cost", l.layoutCost},
                      {"binary_tsah_cost", l.binaryCost}};
  if (l.layout != Layout::Bvh2) j["isa"] = name(l.isa);
  return j;
}

}  // namespace

std::unique_ptr<CpuRuntime> makeRuntime(const anim::Animation& a, const Bvh& tree, const RuntimeSetup& setup,
                                        Layout layout) {
  return std::make_unique<CpuRuntime>(flattenBvh(tree), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                      a.vertexCount(), runtimeConfig(a, setup, layout));
}

std::vector<RuntimeMethod> runCpuMethods(const anim::Animation& a, const std::vector<CpuMethodSpec>& specs,
                                         const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup, Image* image,
                                         std::size_t imageMethod, uint32_t imageFrame) {
  std::vector<RuntimeMethod> results;
  std::vector<std::unique_ptr<cli::FrameRuntime>> runtimes;
  for (const CpuMethodSpec& spec : specs) {
    results.push_back({spec.trees.name, spec.trees.label, spec.rebuild ? "rebuild" : "refit", {}, nlohmann::json::object()});
    cli::FrameRuntimeOptions options;
    options.layout = setup.layout;
    options.threads = setup.threads;
    options.objective = setup.collapse;  // the wide layouts' collapse
    if (spec.rebuild) {
      // A rebuild replaces the first tree every frame: the sweep SAH collapsed like the T-SAH tree,
      // or the binned SAH with its own leaf rule.
      options.rebuild = *spec.rebuild == CpuRebuild::Binned ? cli::Rebuild::Binned : cli::Rebuild::Sweep;
      options.objective.cost = cost;
      options.objective.maxLeafSize = maxLeaf;
      RefitTrees first = spec.trees;
      first.trees.resize(1);
      first.ranges.clear();
      runtimes.push_back(cli::makeFrameRuntime(treeSetOf(first, a), a, options));
    } else {
      runtimes.push_back(cli::makeFrameRuntime(treeSetOf(spec.trees, a), a, options));
    }
    runtimes.back()->warmUp(setup.times.front(), setup.camera, setup.lighting, setup.settings);
  }
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    reportFrame(setup, "all methods", f);
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    for (std::size_t k = 0; k < runtimes.size(); ++k) {
      const std::size_t m = (k + f) % runtimes.size();  // rotated: no method is always first or last
      const cli::FrameUpdate u = runtimes[m]->update(t);
      results[m].frames.push_back(
          timeFrame(*runtimes[m], setup, t, u.updateMs, settings, image && m == imageMethod && f == imageFrame ? image : nullptr));
    }
  }
  return results;
}

std::vector<RuntimeMethod> runEmbreeComparison(const anim::Animation& a, const Bvh& tree, const std::string& name,
                                               const std::string& label, const RuntimeSetup& setup,
                                               const RefitTrees* set) {
  std::vector<RuntimeMethod> methods;
#if TSAH_HAVE_EMBREE
  // One toolkit runtime per layout (the default first: the rays are made with it and every other
  // method's results are compared with its), then one Embree peer per mode.
  std::vector<std::unique_ptr<CpuRuntime>> own;
  for (Layout layout : comparedLayouts(setup.layout)) {
    own.push_back(makeRuntime(a, tree, setup, layout));
    methods.push_back({name + "-" + tsah::name(layout), layoutLabel(label, *own.back()), "refit", {},
                       {{"layout", layoutJson(*own.back())}, {"default_layout", layout == setup.layout}}});
  }
  if (set && set->trees.size() > 1) {  // the tree set: switches to each frame's tree
    own.push_back(makeSetRuntime(a, *set, setup));
    methods.push_back({set->name + "-" + tsah::name(setup.layout), layoutLabel(set->label, *own.back()), "refit", {},
                       {{"layout", layoutJson(*own.back())}, {"trees", set->trees.size()}}});
  }
  startWorkers(*own.front());
  using Mode = EmbreePeer::Mode;
  std::vector<std::unique_ptr<EmbreePeer>> peers;
  for (Mode mode : {Mode::RebuildMedium, Mode::RebuildHigh, Mode::Refit}) {
    peers.push_back(std::make_unique<EmbreePeer>(a.indices(), a.vertexCount(), mode, own.front()->threadCount()));
    const std::string quality = mode == Mode::RebuildMedium ? "medium" : mode == Mode::RebuildHigh ? "high" : "refit";
    methods.push_back({EmbreePeer::modeName(mode),
                       mode == Mode::Refit ? "Embree refit" : "Embree rebuild (" + quality + ")",
                       mode == Mode::Refit ? "refit" : "rebuild",
                       {},
                       {{"build_quality", quality}}});
  }
  // Differences in what the rays found, each method vs the default toolkit layout, over the frames.
  const std::size_t others = own.size() - 1 + peers.size();
  std::vector<std::array<int64_t, 3>> differences(others, {0, 0, 0});
  std::vector<float> positions = a.positionsAt(a.startTime());  // static vertices once
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    reportFrame(setup, "toolkit vs Embree", f);
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    // Every method's update includes the same interpolation of the frame's vertices.
    auto start = std::chrono::steady_clock::now();
    a.movingPositionsAt(t, positions);
    const double interpolateMs = msSince(start);

    // The toolkit: refit + Woop per layout; the batch is made from the default layout's primary
    // hits (untimed), then every method traces it.
    std::vector<double> updateMs(own.size());
    for (std::size_t i = 0; i < own.size(); ++i) {
      // Rotated per frame, as in runCpuMethods: the layout updated first after the interpolation
      // (and after the previous frame's traces of every other method) is not always the same one.
      const std::size_t k = (i + f) % own.size();
      startWorkers(*own.front());  // every timed update starts with the workers awake, Embree's too
      start = std::chrono::steady_clock::now();
      own[k]->selectTreeAt(t);  // a tree set: the tree of this frame's part (a single tree: no-op)
      own[k]->update(positions);
      updateMs[k] = interpolateMs + msSince(start);
    }
    const RayBatch batch = makeRayBatch(*own.front(), setup.camera(t), setup.lighting, settings);
    BatchTrace reference;
    for (std::size_t m = 0; m < own.size() + peers.size(); ++m) {
      FrameTiming ft;
      ft.time = t;
      BatchTrace trace;
      if (m < own.size()) {
        ft.updateMs = updateMs[m];
        trace = traceBatch(*own.front(), batch, toolkitTracer(*own[m]));
      } else {
        startWorkers(*own.front());
        ft.updateMs = interpolateMs + peers[m - own.size()]->update(positions);
        trace = traceBatch(*own.front(), batch, peers[m - own.size()]->tracer());
      }
      ft.rays = {trace.primary, trace.ao, trace.shadow, 0.0};
      ft.traceMs = trace.total().ms;
      ft.totalMs = ft.updateMs + ft.traceMs;
      methods[m].frames.push_back(ft);
      if (m == 0) {
        reference = trace;
        continue;
      }
      differences[m - 1][0] += int64_t(trace.primaryHits) - int64_t(reference.primaryHits);
      differences[m - 1][1] += int64_t(trace.aoOccluded) - int64_t(reference.aoOccluded);
      differences[m - 1][2] += int64_t(trace.shadowOccluded) - int64_t(reference.shadowOccluded);
    }
  }
  for (std::size_t m = 1; m < methods.size(); ++m)
    methods[m].extra["hits_minus_toolkit"] = {{"primary", differences[m - 1][0]},
                                              {"ao_occluded", differences[m - 1][1]},
                                              {"shadow_occluded", differences[m - 1][2]}};
#else
  (void)a;
  (void)tree;
  (void)name;
  (void)label;
  (void)setup;
  (void)set;
#endif
  return methods;
}

}  // namespace tsah::bench
