// The motion-blur part of the bench (motion_bench.hpp): the toolkit's refit at the shutter's keys
// against Embree's motion-blur BVH, on the same rays at the same times.
#include "bench/motion_bench.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>

#include "bench/embree_motion.hpp"
#include "bench/embree_peer.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"

namespace tsah::bench {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

bool nearlyEqual(float a, float b) {
  return std::fabs(a - b) <= kTieRelative * std::max(std::fabs(a), std::fabs(b));
}

void countSame(const std::vector<uint8_t>& own, const std::vector<uint8_t>& other, Agreement& a) {
  a.occlusionRays += own.size();
  for (std::size_t i = 0; i < own.size() && i < other.size(); ++i) a.occlusionSame += own[i] == other[i] ? 1u : 0u;
}

}  // namespace

void Agreement::add(const BatchTrace& own, const BatchTrace& other) {
  primaryRays += own.closest.size();
  for (std::size_t i = 0; i < own.closest.size() && i < other.closest.size(); ++i) {
    const Hit& a = own.closest[i];
    const Hit& b = other.closest[i];
    if (a.tri == b.tri)
      ++primarySame;
    else if (a.valid() != b.valid())
      ++oneMisses;
    else if (nearlyEqual(a.t, b.t))
      ++ties;
    else
      ++otherDepth;
  }
  countSame(own.aoResults, other.aoResults, *this);
  countSame(own.shadowResults, other.shadowResults, *this);
}

nlohmann::json toJson(const Agreement& a) {
  return {{"rays", a.rays()},
          {"same", a.same()},
          {"fraction", a.fraction()},
          {"primary", {{"rays", a.primaryRays}, {"same_triangle", a.primarySame}}},
          {"occlusion", {{"rays", a.occlusionRays}, {"same", a.occlusionSame}}},
          {"differing",
           {{"tie", a.ties}, {"one_misses", a.oneMisses}, {"other_depth", a.otherDepth},
            {"occlusion", a.occlusionRays - a.occlusionSame}}}};
}

nlohmann::json runMotionBlurComparison(const anim::Animation& a, const Bvh& tree, const std::string& label,
                                       const RuntimeSetup& setup, const Shutter& shutter) {
  if (setup.times.size() < 2)
    throw tsah::ConfigError("motion blur: the shutter is a fraction of the time between frames; trace two or more");
  if (!(shutter.fraction > 0.0 && shutter.fraction <= 1.0))
    throw tsah::ConfigError("motion blur: the shutter fraction must lie in (0, 1]");
  const double interval = setup.times[1] - setup.times[0];
  // The CPU traces blurred frames in every layout (docs/motion-blur.md, "Layouts"): the bench's.
  const Layout layout = setup.layout;
  const std::unique_ptr<CpuRuntime> rt = makeRuntime(a, tree, setup, layout);
  startWorkers(*rt);

  nlohmann::json j;
  j["shutter"] = {{"fraction", shutter.fraction},
                  {"mode", shutter.mode == Shutter::Mode::Open ? "open" : "centered"}};
  j["frame_interval"] = interval;
  j["frames"] = setup.times.size();
  j["layout"] = name(layout);
  j["embree_status"] = embreeStatus();
  std::vector<RuntimeMethod> methods;
  methods.push_back({"tsah0-mb", label + ", " + name(layout), "refit at the shutter's keys", {}, nlohmann::json::object()});
  nlohmann::json keys = nlohmann::json::array(), refitted = nlohmann::json::array(),
                 refittedMovingOnly = nlohmann::json::array();

#if TSAH_HAVE_EMBREE
  // Embree's time of a shutter fraction: the animation's time, mapped onto the keyframes' evenly
  // spaced time steps (built once) or onto the shutter's keys (rebuilt every frame).
  const std::span<const double> keyframes = a.times();
  const std::vector<float> animationKeys = motion::keyFractions(keyframes);
  const double start = keyframes.front(), span = keyframes.back() - keyframes.front();
  EmbreeMotionPeer once(a.indices(), a.vertexCount(), rt->threadCount());
  EmbreeMotionPeer perFrame(a.indices(), a.vertexCount(), rt->threadCount());
  startWorkers(*rt);
  const double onceBuildMs = once.build(a, keyframes);
  j["embree_mb_build"] = {{"ms", onceBuildMs}, {"time_steps", once.timeSteps()}, {"pieces", once.pieces()}};
  methods.push_back({"embree-mb", "Embree motion-blur BVH, built once", "none (built once)", {},
                     {{"build_ms", onceBuildMs}, {"time_steps", once.timeSteps()}}});
  methods.push_back({"embree-mb-rebuild", "Embree motion-blur BVH, rebuilt every frame (medium)", "rebuild", {},
                     {{"build_quality", "medium"}}});
  std::array<Agreement, 2> agreement;
#endif

  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    reportFrame(setup, "motion blur", f);
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    const auto [open, close] = shutterInterval(a, t, interval, shutter);
    startWorkers(*rt);
    auto began = std::chrono::steady_clock::now();
    updateShutter(*rt, a, open, close);  // the positions at every key and the refit at each
    const double updateMs = msSince(began);
    const std::vector<double> shutterKeys = motion::shutterKeys(a.times(), open, close);
    keys.push_back(shutterKeys.size());
    refitted.push_back(rt->blurred() ? rt->keysRefitted() : 1u);  // the others reused from the frame before
    refittedMovingOnly.push_back(rt->blurred() ? rt->keysRefittedMovingOnly() : 0u);
    // Made from the toolkit's blurred frame (untimed); an instant shutter (open == close) is time 0.
    RayBatch batch = makeRayBatch(*rt, setup.camera(t), setup.lighting, settings);
    if (batch.times.empty())
      batch.times = {std::vector<float>(batch.primary.size(), 0.0f), std::vector<float>(batch.ao.size(), 0.0f),
                     std::vector<float>(batch.shadow.size(), 0.0f)};
    const BatchTrace own = traceBatch(*rt, batch, toolkitTracer(*rt));
    methods[0].frames.push_back(frameOf(t, updateMs, own));
#if TSAH_HAVE_EMBREE
    const RayTimes onceTimes = mapTimes(batch.times, [&](float tau) {
      const double time = open + double(tau) * (close - open);
      return embreeStepTime(animationKeys, span > 0.0 ? float((time - start) / span) : 0.0f);
    });
    const std::vector<float> fractions = motion::keyFractions(shutterKeys);
    const RayTimes frameTimes = mapTimes(batch.times, [&](float tau) { return embreeStepTime(fractions, tau); });
    // The two Embree passes in an order rotated every frame, as the other comparisons do.
    for (std::size_t k = 0; k < 2; ++k) {
      const std::size_t m = (k + f) % 2;
      startWorkers(*rt);
      if (m == 0) {
        const BatchTrace trace = traceBatch(*rt, batch, once.tracer(), &onceTimes);
        methods[1].frames.push_back(frameOf(t, 0.0, trace));
        agreement[0].add(own, trace);
      } else {
        const double buildMs = perFrame.build(a, shutterKeys);  // interpolation at the keys + build
        const BatchTrace trace = traceBatch(*rt, batch, perFrame.tracer(), &frameTimes);
        methods[2].frames.push_back(frameOf(t, buildMs, trace));
        agreement[1].add(own, trace);
      }
    }
#endif
  }
  j["keys_per_frame"] = keys;
  j["keys_refitted_per_frame"] = refitted;
  j["keys_refitted_moving_only_per_frame"] = refittedMovingOnly;
  j["methods"] = nlohmann::json::array();
#if TSAH_HAVE_EMBREE
  methods[1].extra["agreement"] = toJson(agreement[0]);
  methods[2].extra["agreement"] = toJson(agreement[1]);
  // The target's ratios: trace rate against the motion-blur BVH built once, frame time against
  // the per-frame rebuild.
  j["ratios"] = {{"toolkit_rate_over_embree_mb_rate", traceRate(methods[0]) / std::max(traceRate(methods[1]), 1e-12)},
                 {"toolkit_total_over_embree_rebuild_total",
                  averageTotalMs(methods[0]) / std::max(averageTotalMs(methods[2]), 1e-12)}};
#endif
  for (const RuntimeMethod& m : methods) j["methods"].push_back(toJson(m));
  return j;
}

}  // namespace tsah::bench
