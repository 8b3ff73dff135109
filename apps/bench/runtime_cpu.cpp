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

#if TSAH_HAVE_EMBREE
void report(const RuntimeSetup& setup, const std::string& label, std::size_t frame) {
  if (setup.progress && (frame == 0 || (frame + 1) % 10 == 0 || frame + 1 == setup.times.size()))
    setup.progress(label + ": frame " + std::to_string(frame + 1) + "/" + std::to_string(setup.times.size()));
}
#endif

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

namespace {

// One method's state during the frame-by-frame run.
struct CpuRunner {
  RuntimeMethod result;
  std::vector<std::unique_ptr<CpuRuntime>> runtimes;  // one, or one per segment
  std::vector<TimeSegment> segments;
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
    for (const Bvh* tree : spec.trees.trees) {
      r.runtimes.push_back(makeRuntime(a, *tree, setup.threads));
      if (spec.rebuild) break;  // a rebuild replaces the tree anyway
    }
    r.segments = spec.rebuild ? std::vector<TimeSegment>{} : spec.trees.segments;
    if (spec.rebuild) r.builder = rebuildBuilder(*spec.rebuild, cost, maxLeaf);
    r.positions = a.positionsAt(a.startTime());  // static vertices once; each frame writes the moving ones
    startWorkers(*r.runtimes.front());
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
      CpuRuntime& rt = *r.runtimes[r.segments.empty() ? 0 : segmentOf(r.segments, t)];
      FrameTiming ft;
      ft.time = t;
      const auto start = std::chrono::steady_clock::now();
      a.movingPositionsAt(t, r.positions);
      if (r.builder)
        rt.rebuild(r.positions, r.builder);
      else
        rt.update(r.positions);
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
