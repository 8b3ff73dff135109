// The CPU side of the runtime benchmark: CpuRuntime + renderFrame per method, and the Embree peer.
#include <array>
#include <chrono>
#include <memory>

#include "bench/embree_peer.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/cpu_runtime.hpp"
#include "tsah/flat_bvh.hpp"
#include "tsah/leaf_collapser.hpp"
#include "tsah/sah_builder.hpp"

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

void report(const RuntimeSetup& setup, const std::string& label, std::size_t frame) {
  if (setup.progress && (frame == 0 || (frame + 1) % 10 == 0 || frame + 1 == setup.times.size()))
    setup.progress(label + ": frame " + std::to_string(frame + 1) + "/" + std::to_string(setup.times.size()));
}

std::unique_ptr<CpuRuntime> makeRuntime(const anim::Animation& a, const Bvh& tree, unsigned threads) {
  return std::make_unique<CpuRuntime>(flattenBvh(tree), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                      a.vertexCount(), CpuRuntime::Config{threads});
}

}  // namespace

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

RuntimeMethod runCpuRefit(const anim::Animation& a, const RefitTrees& trees, const RuntimeSetup& setup, Image* image,
                          uint32_t imageFrame) {
  std::vector<std::unique_ptr<CpuRuntime>> runtimes;
  for (const Bvh* tree : trees.trees) runtimes.push_back(makeRuntime(a, *tree, setup.threads));
  startWorkers(*runtimes.front());
  RuntimeMethod m{trees.name, trees.label, "refit", {}, nlohmann::json::object()};
  std::vector<float> positions(std::size_t(a.vertexCount()) * 3);
  Image scratch;
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    report(setup, trees.label, f);
    const double t = setup.times[f];
    CpuRuntime& rt = *runtimes[trees.segments.empty() ? 0 : segmentOf(trees.segments, t)];
    FrameTiming ft;
    ft.time = t;
    const auto start = std::chrono::steady_clock::now();
    a.positionsAt(t, positions);
    rt.update(positions);
    ft.updateMs = msSince(start);
    settings.frame = static_cast<uint32_t>(f);
    Image& target = image && f == imageFrame ? *image : scratch;
    ft.rays = renderFrame(rt, setup.camera(t), setup.lighting, settings, target);
    ft.traceMs = ft.rays.total().ms;
    ft.totalMs = ft.updateMs + ft.traceMs;
    m.frames.push_back(ft);
  }
  return m;
}

RuntimeMethod runCpuRebuild(const anim::Animation& a, const Bvh& initialTree, CpuRebuild kind, const CostModel& cost,
                            uint32_t maxLeaf, const RuntimeSetup& setup) {
  CpuRuntime::TreeBuilder builder;
  RuntimeMethod m;
  m.update = "rebuild";
  if (kind == CpuRebuild::Binned) {
    BinnedSahBuilder::Config c;
    c.cost = cost;
    c.maxLeafSize = maxLeaf;
    builder = [c](std::span<const Aabb> boxes) { return BinnedSahBuilder(c).build(boxes); };
    m.name = "rebuild-binned";
    m.label = "binned SAH rebuild";
  } else {
    SweepSahBuilder::Config s;
    s.cost = cost;
    LeafCollapser::Config l;
    l.cost = cost;
    l.maxLeafSize = maxLeaf;
    builder = [s, l](std::span<const Aabb> boxes) { return LeafCollapser(l).collapse(SweepSahBuilder(s).build(boxes)); };
    m.name = "rebuild-sweep";
    m.label = "sweep SAH rebuild";
  }
  auto rt = makeRuntime(a, initialTree, setup.threads);
  startWorkers(*rt);
  std::vector<float> positions(std::size_t(a.vertexCount()) * 3);
  Image scratch;
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    report(setup, m.label, f);
    const double t = setup.times[f];
    FrameTiming ft;
    ft.time = t;
    const auto start = std::chrono::steady_clock::now();
    a.positionsAt(t, positions);
    rt->rebuild(positions, builder);
    ft.updateMs = msSince(start);
    settings.frame = static_cast<uint32_t>(f);
    ft.rays = renderFrame(*rt, setup.camera(t), setup.lighting, settings, scratch);
    ft.traceMs = ft.rays.total().ms;
    ft.totalMs = ft.updateMs + ft.traceMs;
    m.frames.push_back(ft);
  }
  return m;
}

std::vector<RuntimeMethod> runEmbreeComparison(const anim::Animation& a, const Bvh& tree, const std::string& name,
                                               const std::string& label, const RuntimeSetup& setup) {
  std::vector<RuntimeMethod> methods;
#if TSAH_HAVE_EMBREE
  auto rt = makeRuntime(a, tree, setup.threads);
  startWorkers(*rt);
  const BatchTracer toolkit = toolkitTracer(*rt);
  using Mode = EmbreePeer::Mode;
  std::vector<std::unique_ptr<EmbreePeer>> peers;
  methods.push_back({name, label, "refit", {}, nlohmann::json::object()});
  for (Mode mode : {Mode::RebuildMedium, Mode::RebuildHigh, Mode::Refit}) {
    peers.push_back(std::make_unique<EmbreePeer>(a.indices(), a.vertexCount(), mode, rt->threadCount()));
    const std::string quality = mode == Mode::RebuildMedium ? "medium" : mode == Mode::RebuildHigh ? "high" : "refit";
    methods.push_back({EmbreePeer::modeName(mode),
                       mode == Mode::Refit ? "Embree refit" : "Embree rebuild (" + quality + ")",
                       mode == Mode::Refit ? "refit" : "rebuild",
                       {},
                       {{"build_quality", quality}}});
  }
  // Differences in what the rays found, Embree vs the toolkit, summed over the frames.
  std::vector<std::array<int64_t, 3>> differences(peers.size(), {0, 0, 0});
  std::vector<float> positions(std::size_t(a.vertexCount()) * 3);
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    report(setup, "toolkit vs Embree", f);
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    // Every method's update includes the same interpolation of the frame's vertices.
    auto start = std::chrono::steady_clock::now();
    a.positionsAt(t, positions);
    const double interpolateMs = msSince(start);

    // The toolkit: refit + Woop, then the batch (rays made from its primary hits, untimed).
    FrameTiming own;
    own.time = t;
    start = std::chrono::steady_clock::now();
    rt->update(positions);
    own.updateMs = interpolateMs + msSince(start);
    const RayBatch batch = makeRayBatch(*rt, setup.camera(t), setup.lighting, settings);
    const BatchTrace ownTrace = traceBatch(*rt, batch, toolkit);
    own.rays = {ownTrace.primary, ownTrace.ao, ownTrace.shadow, 0.0};
    own.traceMs = ownTrace.total().ms;
    own.totalMs = own.updateMs + own.traceMs;
    methods[0].frames.push_back(own);

    for (std::size_t p = 0; p < peers.size(); ++p) {
      FrameTiming ft;
      ft.time = t;
      ft.updateMs = interpolateMs + peers[p]->update(positions);
      const BatchTrace trace = traceBatch(*rt, batch, peers[p]->tracer());
      ft.rays = {trace.primary, trace.ao, trace.shadow, 0.0};
      ft.traceMs = trace.total().ms;
      ft.totalMs = ft.updateMs + ft.traceMs;
      methods[p + 1].frames.push_back(ft);
      differences[p][0] += int64_t(trace.primaryHits) - int64_t(ownTrace.primaryHits);
      differences[p][1] += int64_t(trace.aoOccluded) - int64_t(ownTrace.aoOccluded);
      differences[p][2] += int64_t(trace.shadowOccluded) - int64_t(ownTrace.shadowOccluded);
    }
  }
  for (std::size_t p = 0; p < peers.size(); ++p)
    methods[p + 1].extra["hits_minus_toolkit"] = {
        {"primary", differences[p][0]}, {"ao_occluded", differences[p][1]}, {"shadow_occluded", differences[p][2]}};
#else
  (void)a;
  (void)tree;
  (void)name;
  (void)label;
  (void)setup;
#endif
  return methods;
}

}  // namespace tsah::bench
