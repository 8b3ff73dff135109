// What the CPU and GPU halves of the runtime benchmark share: the trees as a set, one timed frame,
// progress, and a method's JSON.
#include "bench/runtime_bench.hpp"
#include "bench/ray_batch.hpp"
#include "frame_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah::bench {

namespace {

nlohmann::json ratesJson(const RenderStats& s) {
  return {{"primary", s.primary.mraysPerSecond()},
          {"ao", s.ao.mraysPerSecond()},
          {"shadow", s.shadow.mraysPerSecond()},
          {"total", s.total().mraysPerSecond()}};
}

}  // namespace

FrameTiming timeFrame(cli::FrameRuntime& runtime, const RuntimeSetup& setup, double time, double updateMs,
                      const RenderSettings& settings, Image* image) {
  FrameTiming ft;
  ft.time = time;
  ft.updateMs = updateMs;
  const cli::FrameRender r = runtime.render(setup.camera(time), setup.lighting, settings, nullptr);
  ft.rays = r.rays;
  ft.traceMs = r.rays.total().ms;
  ft.totalMs = updateMs + r.frameMs;
  if (image) runtime.render(setup.camera(time), setup.lighting, settings, image);
  return ft;
}

void reportFrame(const RuntimeSetup& setup, const std::string& label, std::size_t frame) {
  if (setup.progress && (frame == 0 || (frame + 1) % 10 == 0 || frame + 1 == setup.times.size()))
    setup.progress(label + ": frame " + std::to_string(frame + 1) + "/" + std::to_string(setup.times.size()));
}

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

FrameTiming frameOf(double time, double updateMs, const BatchTrace& trace) {
  FrameTiming ft;
  ft.time = time;
  ft.updateMs = updateMs;
  ft.rays = {trace.primary, trace.ao, trace.shadow, 0.0};
  ft.traceMs = trace.total().ms;
  ft.totalMs = updateMs + ft.traceMs;
  return ft;
}

double averageTotalMs(const RuntimeMethod& m) {
  double sum = 0.0;
  for (const FrameTiming& f : m.frames) sum += f.totalMs;
  return m.frames.empty() ? 0.0 : sum / double(m.frames.size());
}

double traceRate(const RuntimeMethod& m) {
  double rays = 0.0, ms = 0.0;
  for (const FrameTiming& f : m.frames) {
    rays += double(f.rays.total().rays);
    ms += f.rays.total().ms;
  }
  return ms > 0.0 ? rays / (ms * 1e3) : 0.0;
}

}  // namespace tsah::bench
