// tsah_query_bench: closest-point and box-overlap queries per second on one frame of a scene, on
// the CPU runtime (every supported layout, all threads) and the GPU runtime (when built and a
// device is present), printed as one JSON object (docs/bench.md). Queries: random points within
// the frame's bounds; closest points with a radius of 1 % and 10 % of the bounds' diagonal; boxes
// centred on the points with edges of 1 % and 10 % of the diagonal.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "anim/load.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/queries.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_queries.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace {

using json = nlohmann::json;

struct Options {
  std::string input, tree;
  uint32_t queries = 1u << 20;
  uint32_t threads = 0;
  uint32_t repeat = 3;
  double time = NAN;  // default: the middle of the animation
  bool noGpu = false;
};

struct Workload {
  std::vector<tsah::Vec3> points;
  float diagonal = 0.0f;
  std::vector<tsah::Aabb> boxesAround(float edge) const {
    std::vector<tsah::Aabb> boxes(points.size());
    const tsah::Vec3 half{0.5f * edge, 0.5f * edge, 0.5f * edge};
    for (std::size_t i = 0; i < points.size(); ++i) boxes[i] = {points[i] - half, points[i] + half};
    return boxes;
  }
};

// The best of `repeat` runs of fn (seconds).
template <class Fn>
double bestSeconds(uint32_t repeat, Fn&& fn) {
  double best = INFINITY;
  for (uint32_t r = 0; r < repeat; ++r) {
    const auto start = std::chrono::steady_clock::now();
    fn();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  return best;
}

// Queries per second of closest points (both radii) and boxes (both edges) through `closest` and
// `overlap`, each setting the device seconds of its kernels when it has them (the GPU: reported
// beside the wall time, which includes the transfers).
template <class Closest, class Overlap>
json measure(const Workload& w, uint32_t repeat, Closest&& closest, Overlap&& overlap) {
  json out;
  const double n = double(w.points.size());
  for (const auto& [key, fraction] : {std::pair{"1pct", 0.01f}, std::pair{"10pct", 0.1f}}) {
    const std::vector<float> radius{fraction * w.diagonal};
    uint64_t found = 0;
    double device = INFINITY;
    const double wall = bestSeconds(repeat, [&] {
      found = 0;
      double d = 0.0;
      for (const tsah::PointHit& h : closest(w.points, radius, d)) found += h.valid() ? 1 : 0;
      device = std::min(device, d);
    });
    json& c = out[std::string("closest_") + key];
    c = {{"queries_per_second", n / wall}, {"found_fraction", double(found) / n}};
    if (device > 0.0) c["kernel_queries_per_second"] = n / device;
    const std::vector<tsah::Aabb> boxes = w.boxesAround(fraction * w.diagonal);
    uint64_t triangles = 0;
    device = INFINITY;
    const double boxWall = bestSeconds(repeat, [&] {
      double d = 0.0;
      triangles = overlap(boxes, d).triangles.size();
      device = std::min(device, d);
    });
    json& b = out[std::string("boxes_") + key];
    b = {{"queries_per_second", n / boxWall}, {"triangles_per_box", double(triangles) / n}};
    if (device > 0.0) b["kernel_queries_per_second"] = n / device;
  }
  return out;
}

void run(const Options& opt) {
  const anim::Animation a = anim::load(opt.input);
  const double t = std::isnan(opt.time) ? 0.5 * (a.startTime() + a.endTime()) : opt.time;
  const std::vector<float> positions = a.positionsAt(t);
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  tsah::FlatBvh tree;
  if (!opt.tree.empty()) {
    tree = tsah::flattenBvh(tsah::loadBvhFile(opt.tree).bvh);
  } else {
    std::vector<tsah::Aabb> boxes(a.triangleCount());
    tsah::triangleBoxes(indices, positions, boxes);
    tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(boxes));
  }
  Workload w;
  tsah::Aabb bounds;
  for (std::size_t v = 0; v < positions.size(); v += 3) bounds.extend(tsah::Vec3{positions[v], positions[v + 1], positions[v + 2]});
  const tsah::Vec3 size = bounds.extent();
  w.diagonal = std::sqrt(tsah::dot(size, size));
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (uint32_t i = 0; i < opt.queries; ++i) w.points.push_back(bounds.lo + tsah::Vec3{u(rng) * size.x, u(rng) * size.y, u(rng) * size.z});

  json out = {{"scene", opt.input}, {"triangles", a.triangleCount()}, {"time", t}, {"queries", opt.queries},
              {"tree", opt.tree.empty() ? "binned SAH of the frame" : opt.tree}};
  for (tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    if (!tsah::layoutSupported(layout)) continue;
    tsah::CpuRuntime::Config config(opt.threads);
    config.layout = layout;
    tsah::CpuRuntime rt(tree, indices, a.vertexCount(), config);
    rt.update(positions);
    json cpu = measure(
        w, opt.repeat, [&](const auto& p, const auto& r, double&) { return tsah::closestPoints(rt, p, r); },
        [&](const auto& b, double&) { return tsah::overlappingTriangles(rt, b); });
    cpu["threads"] = rt.threadCount();
    out["cpu"][tsah::name(layout)] = cpu;
  }
#if defined(TSAH_HAVE_CUDA)
  if (!opt.noGpu && tsah::cuda::deviceAvailable()) {
    tsah::cuda::GpuRuntime gpu(tree, a);
    gpu.update(positions);
    tsah::RayPassStats stats;
    json g = measure(
        w, opt.repeat,
        [&](const auto& p, const auto& r, double& device) {
          auto hits = tsah::cuda::closestPoints(gpu, p, r, &stats);
          device = stats.ms * 1e-3;
          return hits;
        },
        [&](const auto& b, double& device) {
          auto found = tsah::cuda::overlappingTriangles(gpu, b, &stats);
          device = stats.ms * 1e-3;
          return found;
        });
    g["device"] = gpu.device().name;
    out["gpu"] = g;
  }
#endif
  std::cout << out.dump(1) << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tsah_query_bench: closest-point and box-overlap queries per second as one JSON object"};
  Options opt;
  app.add_option("input", opt.input, "Animation file (.tanim or anything tsah reads)")->required();
  app.add_option("--tree", opt.tree, "A .tbvh tree of the animation (default: a binned SAH tree of the timed frame)");
  app.add_option("--time", opt.time, "The frame's time (default: the middle of the animation)");
  app.add_option("--queries", opt.queries, "Query points (default 1048576)")->check(CLI::Range(1u, 1u << 30));
  app.add_option("--threads", opt.threads, "CPU worker threads (default 0: one per hardware thread)");
  app.add_option("--repeat", opt.repeat, "Runs of each measurement; the best counts (default 3)")->check(CLI::Range(1u, 100u));
  app.add_flag("--no-gpu", opt.noGpu, "Skip the GPU even when one is present");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    run(opt);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tsah_query_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
