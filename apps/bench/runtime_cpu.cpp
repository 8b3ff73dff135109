// The CPU side of the runtime benchmark: CpuRuntime + renderFrame per method, and the Embree peer.
#include <array>
#include <chrono>
#include <memory>

#include "bench/embree_peer.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"

namespace tsah::bench {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

nlohmann::json ratesJson(const RenderStats& s) {
  return {{"primary", s.primary.mraysPerSecond()},
          {"ao", s.ao.mraysPerSecond()},
          {"shadow", s.shadow.mraysPerSecond()},
          {"total", s.total().mraysPerSecond()}};
}

void startWorkers(const CpuRuntime& rt) {
  rt.parallelFor(rt.threadCount() * 4, 1, [](std::size_t, std::size_t) {});  // before anything is timed
}

#if TSAH_HAVE_EMBREE
void report(const RuntimeSetup& setup, const std::string& label, std::size_t frame) {
  if (setup.progress && (frame == 0 || (frame + 1) % 10 == 0 || frame + 1 == setup.times.size()))
    setup.progress(label + ": frame " + std::to_string(frame + 1) + "/" + std::to_string(setup.times.size()));
}
#endif

CpuRuntime::Config runtimeConfig(const RuntimeSetup& setup, CpuLayout layout) {
  CpuRuntime::Config c(setup.threads);
  c.layout = layout;
  c.collapse = setup.collapse;
  return c;
}

std::unique_ptr<CpuRuntime> makeRuntime(const anim::Animation& a, const Bvh& tree, const RuntimeSetup& setup,
                                        CpuLayout layout) {
  return std::make_unique<CpuRuntime>(flattenBvh(tree), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                      a.vertexCount(), runtimeConfig(setup, layout));
}

// A tree set's runtime (each frame selects the tree of its part).
std::unique_ptr<CpuRuntime> makeSetRuntime(const anim::Animation& a, const RefitTrees& trees, const RuntimeSetup& setup) {
  return std::make_unique<CpuRuntime>(treeSetOf(trees, a), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                      a.vertexCount(), runtimeConfig(setup, setup.layout));
}

// "LABEL, bvh8, avx512": the layout and, for a wide one, its kernels.
std::string layoutLabel(const std::string& label, const CpuRuntime& rt) {
  const LayoutInfo& l = rt.layoutInfo();
  return label + ", " + layoutName(l.layout) + (l.layout == CpuLayout::Bvh2 ? "" : std::string(", ") + isaName(l.isa));
}

// The toolkit's layouts for the Embree comparison: the default (fastest) one first.
std::vector<CpuLayout> comparedLayouts(CpuLayout first) {
  std::vector<CpuLayout> out{first};
  for (CpuLayout l : {CpuLayout::Bvh8, CpuLayout::Bvh4, CpuLayout::Bvh2})
    if (l != first && layoutSupported(l)) out.push_back(l);
  return out;
}

nlohmann::json layoutJson(const CpuRuntime& rt) {
  const LayoutInfo& l = rt.layoutInfo();
  nlohmann::json j = {{"layout", layoutName(l.layout)},
                      {"interior_nodes", l.interiorNodes},
                      {"leaves", l.leaves},
                      {"depth", l.depth},
                      {"tsah_cost", l.layoutCost},
                      {"binary_tsah_cost", l.binaryCost}};
  if (l.layout != CpuLayout::Bvh2) j["isa"] = isaName(l.isa);
  return j;
}

}  // namespace

TreeSet treeSetOf(const RefitTrees& trees, const anim::Animation& a) {
  TreeSet set;
  for (const Bvh* tree : trees.trees) set.trees.push_back(flattenBvh(*tree));
  set.ranges = trees.ranges;
  if (set.ranges.empty()) set.ranges = {{a.startTime(), a.endTime()}};
  return set;
}

nlohmann::json toJson(const RuntimeMethod& m) {
  nlohmann::json j;
  j["name"] = m.name;
  j["label"] = m.label;
  j["update"] = m.update;
  RenderStats sum;
  double update = 0.0, trace = 0.0, total = 0.0;
  nlohmann::json times = nlohmann::json::array(), updates = nlohmann::json::array(), traces = nlohmann::json::array(),
                 totals = nlohmann::json::array(), rates = nlohmann::json::array();
  for (const FrameTiming& f : m.frames) {
    update += f.updateMs;
    trace += f.traceMs;
    total += f.totalMs;
    for (auto [s, p] : {std::pair{&sum.primary, &f.rays.primary}, std::pair{&sum.ao, &f.rays.ao},
                        std::pair{&sum.shadow, &f.rays.shadow}}) {
      s->rays += p->rays;
      s->ms += p->ms;
    }
    times.push_back(f.time);
    updates.push_back(f.updateMs);
    traces.push_back(f.traceMs);
    totals.push_back(f.totalMs);
    rates.push_back(f.rays.total().mraysPerSecond());
  }
  const double n = m.frames.empty() ? 1.0 : double(m.frames.size());
  j["frames"] = m.frames.size();
  j["average"] = {{"update_ms", update / n},
                  {"trace_ms", trace / n},
                  {"total_ms", total / n},
                  {"mrays_per_s", ratesJson(sum)},
                  {"rays_per_frame",
                   {{"primary", double(sum.primary.rays) / n},
                    {"ao", double(sum.ao.rays) / n},
                    {"shadow", double(sum.shadow.rays) / n},
                    {"total", double(sum.total().rays) / n}}}};
  j["per_frame"] = {{"time", times}, {"update_ms", updates}, {"trace_ms", traces}, {"total_ms", totals},
                    {"mrays_per_s", rates}};
  if (!m.extra.empty()) j["extra"] = m.extra;
  return j;
}

namespace {

// One method's state during the frame-by-frame run.
struct CpuRunner {
  RuntimeMethod result;
  std::unique_ptr<CpuRuntime> runtime;                // refit: the tree or tree set; rebuild: the initial tree
  CpuRuntime::TreeBuilder builder;                    // set for rebuilds
  std::vector<float> positions;
  Image scratch;
};

CpuRuntime::TreeBuilder rebuildBuilder(CpuRebuild kind, const CostModel& cost, uint32_t maxLeaf) {
  if (kind == CpuRebuild::Binned) {
    BinnedSahBuilder::Config c;
    c.cost = cost;
    c.maxLeafSize = maxLeaf;
    return [c](std::span<const Aabb> boxes) { return BinnedSahBuilder(c).build(boxes); };
  }
  SweepSahBuilder::Config s;
  s.cost = cost;
  LeafCollapser::Config l;
  l.cost = cost;
  l.maxLeafSize = maxLeaf;
  return [s, l](std::span<const Aabb> boxes) { return LeafCollapser(l).collapse(SweepSahBuilder(s).build(boxes)); };
}

}  // namespace

std::vector<RuntimeMethod> runCpuMethods(const anim::Animation& a, const std::vector<CpuMethodSpec>& specs,
                                         const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup, Image* image,
                                         std::size_t imageMethod, uint32_t imageFrame) {
  std::vector<CpuRunner> runners(specs.size());
  for (std::size_t m = 0; m < specs.size(); ++m) {
    const CpuMethodSpec& spec = specs[m];
    CpuRunner& r = runners[m];
    r.result = {spec.trees.name, spec.trees.label, spec.rebuild ? "rebuild" : "refit", {}, nlohmann::json::object()};
    if (spec.rebuild) {
      r.runtime = makeRuntime(a, *spec.trees.trees.front(), setup, setup.layout);  // a rebuild replaces it anyway
    } else {
      r.runtime = makeSetRuntime(a, spec.trees, setup);
    }
    if (spec.rebuild) r.builder = rebuildBuilder(*spec.rebuild, cost, maxLeaf);
    r.positions = a.positionsAt(a.startTime());  // static vertices once; each frame writes the moving ones
    startWorkers(*r.runtime);
  }
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    if (setup.progress && (f == 0 || (f + 1) % 10 == 0 || f + 1 == setup.times.size()))
      setup.progress("all methods: frame " + std::to_string(f + 1) + "/" + std::to_string(setup.times.size()));
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    for (std::size_t k = 0; k < runners.size(); ++k) {
      const std::size_t m = (k + f) % runners.size();  // rotated: no method is always first or last
      CpuRunner& r = runners[m];
      CpuRuntime& rt = *r.runtime;
      FrameTiming ft;
      ft.time = t;
      const auto start = std::chrono::steady_clock::now();
      a.movingPositionsAt(t, r.positions);
      if (r.builder) {
        rt.rebuild(r.positions, r.builder);
      } else {
        rt.selectTreeAt(t);  // a tree set: the tree of this frame's part
        rt.update(r.positions);
      }
      ft.updateMs = msSince(start);
      Image& target = image && m == imageMethod && f == imageFrame ? *image : r.scratch;
      ft.rays = renderFrame(rt, setup.camera(t), setup.lighting, settings, target);
      ft.traceMs = ft.rays.total().ms;
      ft.totalMs = ft.updateMs + ft.traceMs;
      r.result.frames.push_back(ft);
    }
  }
  std::vector<RuntimeMethod> out;
  for (CpuRunner& r : runners) out.push_back(std::move(r.result));
  return out;
}

std::vector<RuntimeMethod> runEmbreeComparison(const anim::Animation& a, const Bvh& tree, const std::string& name,
                                               const std::string& label, const RuntimeSetup& setup,
                                               const RefitTrees* set) {
  std::vector<RuntimeMethod> methods;
#if TSAH_HAVE_EMBREE
  // One toolkit runtime per layout (the default first: the rays are made with it and every other
  // method's results are compared with its), then one Embree peer per mode.
  std::vector<std::unique_ptr<CpuRuntime>> own;
  for (CpuLayout layout : comparedLayouts(setup.layout)) {
    own.push_back(makeRuntime(a, tree, setup, layout));
    methods.push_back({name + "-" + layoutName(layout), layoutLabel(label, *own.back()), "refit", {},
                       {{"layout", layoutJson(*own.back())}, {"default_layout", layout == setup.layout}}});
  }
  if (set && set->trees.size() > 1) {  // the tree set: switches to each frame's tree
    own.push_back(makeSetRuntime(a, *set, setup));
    methods.push_back({set->name + "-" + layoutName(setup.layout), layoutLabel(set->label, *own.back()), "refit", {},
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
    report(setup, "toolkit vs Embree", f);
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
