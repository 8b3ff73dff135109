#include "tsah/baselines.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "tsah/leaf_collapser.hpp"
#include "tsah/sah_builder.hpp"

namespace tsah {

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

unsigned workerCount(unsigned requested, std::size_t tasks) {
  unsigned n = requested ? requested : std::max(1u, std::thread::hardware_concurrency());
  return static_cast<unsigned>(std::min<std::size_t>(n, std::max<std::size_t>(tasks, 1)));
}

// Runs body(task, worker) for every task in [0, count) on `workers` threads. Tasks are independent,
// so results do not depend on the thread count. The first exception is rethrown here.
template <typename Body>
void parallelFor(std::size_t count, unsigned workers, Body&& body) {
  if (workers <= 1 || count <= 1) {
    for (std::size_t t = 0; t < count; ++t) body(t, 0u);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::exception_ptr failure;
  std::mutex failureMutex;
  const auto run = [&](unsigned worker) {
    for (;;) {
      const std::size_t t = next.fetch_add(1);
      if (t >= count) return;
      try {
        body(t, worker);
      } catch (...) {
        std::lock_guard<std::mutex> lock(failureMutex);
        if (!failure) failure = std::current_exception();
        next.store(count);
      }
    }
  };
  std::vector<std::thread> threads;
  for (unsigned w = 1; w < workers; ++w) threads.emplace_back(run, w);
  run(0);
  for (std::thread& t : threads) t.join();
  if (failure) std::rethrow_exception(failure);
}

// A seed per independent optimization (frame f of method `tag`), so that the trees do not depend on
// which thread built them.
uint64_t derivedSeed(uint64_t seed, uint64_t tag, uint64_t index) {
  uint64_t z = seed ^ (tag * 0x9e3779b97f4a7c15ull) ^ (index * 0xbf58476d1ce4e5b9ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Serializes progress messages from worker threads.
class ProgressSink {
 public:
  explicit ProgressSink(const BaselineConfig& config) : callback_(config.progress) {}
  void operator()(const std::string& message) {
    if (!callback_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    callback_(message);
  }
  bool active() const { return bool(callback_); }

 private:
  std::function<void(const std::string&)> callback_;
  std::mutex mutex_;
};

PrimitiveBoxes singleFrame(std::span<const Aabb> frame) {
  PrimitiveBoxes boxes;
  boxes.frameCount = 1;
  boxes.primCount = static_cast<uint32_t>(frame.size());
  boxes.boxes.assign(frame.begin(), frame.end());
  return boxes;
}

Bvh collapseLeaves(const Bvh& bvh, const BaselineConfig& config, int k) {
  if (config.maxLeafSize <= 1) return bvh;
  return LeafCollapser({config.cost, config.maxLeafSize, k}).collapse(bvh);
}

InsertionOptimizer::Config optimizerConfig(const BaselineConfig& config, int k, uint64_t seed) {
  InsertionOptimizer::Config c = config.optimizer;
  c.cost = config.cost;
  c.k = k;
  c.seed = seed;
  c.progress = nullptr;
  return c;
}

void checkFrames(const PrimitiveBoxes& rep) {
  if (rep.frameCount == 0) throw std::invalid_argument("no representative frames");
  if (rep.boxes.size() != std::size_t(rep.frameCount) * rep.primCount)
    throw std::invalid_argument("representative frame boxes do not match frames x primitives");
}

}  // namespace

FrameSource FrameSource::fromBoxes(const PrimitiveBoxes& boxes) {
  FrameSource source;
  source.frameCount = boxes.frameCount;
  source.primCount = boxes.primCount;
  const PrimitiveBoxes* data = &boxes;
  source.fill = [data](uint32_t frame, std::span<Aabb> out) {
    const std::span<const Aabb> in = data->frame(frame);
    std::copy(in.begin(), in.end(), out.begin());
  };
  return source;
}

FrameSource FrameSource::fromTriangles(std::span<const uint32_t> indices, std::span<const float> positions,
                                       uint32_t frameCount) {
  FrameSource source;
  source.frameCount = frameCount;
  source.primCount = static_cast<uint32_t>(indices.size() / 3);
  const std::size_t perFrame = frameCount ? positions.size() / frameCount : 0;
  source.fill = [indices, positions, perFrame](uint32_t frame, std::span<Aabb> out) {
    triangleBoxes(indices, positions.subspan(std::size_t(frame) * perFrame, perFrame), out);
  };
  return source;
}

std::string MethodSpec::name() const {
  switch (method) {
    case Method::Sah0:
      return "sah0";
    case Method::SahStar:
      return "sahstar";
    case Method::SahRebuild:
      return "rebuild";
    case Method::TSah:
      return "tsah" + std::to_string(k);
  }
  return "?";
}

MethodSpec MethodSpec::parse(const std::string& name) {
  if (name == "sah0") return {Method::Sah0, 0};
  if (name == "sahstar") return {Method::SahStar, 0};
  if (name == "rebuild") return {Method::SahRebuild, 0};
  if (name == "tsah") return {Method::TSah, 0};
  if (name.rfind("tsah", 0) == 0 && name.size() <= 6 &&
      std::all_of(name.begin() + 4, name.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return {Method::TSah, std::stoi(name.substr(4))};
  throw std::invalid_argument("unknown method '" + name +
                              "' (expected sah0, sahstar, rebuild or tsah<k> such as tsah0, tsah2)");
}

Bvh buildSah0(const PrimitiveBoxes& rep, const BaselineConfig& config) {
  checkFrames(rep);
  Bvh bvh = SweepSahBuilder({config.cost, 1}).build(rep.frame(0));
  bvh = collapseLeaves(bvh, config, 0);  // with the cost of frame 0, the only frame SAH0 knows
  refit(bvh, rep);
  return bvh;
}

Bvh buildOptimizedSah(std::span<const Aabb> frame, const BaselineConfig& config, uint64_t seed) {
  const PrimitiveBoxes boxes = singleFrame(frame);
  Bvh bvh = SweepSahBuilder({config.cost, 1}).build(frame);
  InsertionOptimizer::Result result =
      InsertionOptimizer(optimizerConfig(config, 0, seed)).optimize(std::move(bvh), boxes);
  return collapseLeaves(result.bvh, config, 0);
}

Bvh buildSahStar(const PrimitiveBoxes& rep, const BaselineConfig& config) {
  checkFrames(rep);
  ProgressSink progress(config);
  std::vector<Bvh> trees(rep.frameCount);
  std::vector<double> average(rep.frameCount);
  std::atomic<uint32_t> done{0};
  parallelFor(rep.frameCount, workerCount(config.threads, rep.frameCount), [&](std::size_t f, unsigned) {
    Bvh tree = buildOptimizedSah(rep.frame(uint32_t(f)), config,
                                 derivedSeed(config.optimizer.seed, 1, f));
    refit(tree, rep);
    average[f] = temporalCost(frameCosts(tree, config.cost), 0);
    trees[f] = std::move(tree);
    progress("sahstar: " + std::to_string(++done) + "/" + std::to_string(rep.frameCount) + " frames");
  });
  const auto best = std::min_element(average.begin(), average.end()) - average.begin();
  return std::move(trees[std::size_t(best)]);
}

Bvh buildTSah(const PrimitiveBoxes& rep, int k, const BaselineConfig& config,
              InsertionOptimizer::Result* details) {
  checkFrames(rep);
  ProgressSink progress(config);
  Bvh bvh = SweepSahBuilder({config.cost, 1}).build(rep.frame(0));
  InsertionOptimizer::Config oc = optimizerConfig(config, k, config.optimizer.seed);
  const std::string label = "tsah" + std::to_string(k);
  oc.progress = [&](const InsertionOptimizer::BatchRecord& r) {
    if (config.optimizer.progress) config.optimizer.progress(r);
    if (progress.active())
      progress(label + ": batch " + std::to_string(r.batch) + ", cost " + std::to_string(r.cost));
  };
  InsertionOptimizer::Result result = InsertionOptimizer(oc).optimize(std::move(bvh), rep);
  Bvh collapsed = collapseLeaves(result.bvh, config, k);
  if (details) {
    *details = std::move(result);
    details->bvh = Bvh{};
  }
  return collapsed;
}

Bvh buildMethod(const MethodSpec& method, const PrimitiveBoxes& rep, const BaselineConfig& config,
                InsertionOptimizer::Result* details) {
  switch (method.method) {
    case Method::Sah0:
      return buildSah0(rep, config);
    case Method::SahStar:
      return buildSahStar(rep, config);
    case Method::TSah:
      return buildTSah(rep, method.k, config, details);
    case Method::SahRebuild:
      break;
  }
  throw std::invalid_argument("method " + method.name() + " builds one tree per frame, not one tree");
}

std::vector<double> evaluateFrames(const Bvh& bvh, const FrameSource& frames, const CostModel& cost,
                                   unsigned threads) {
  if (frames.primCount != bvh.primCount())
    throw std::invalid_argument("evaluation frames hold " + std::to_string(frames.primCount) +
                                " primitives, the tree " + std::to_string(bvh.primCount()));
  std::vector<double> costs(frames.frameCount, 0.0);
  const unsigned workers = workerCount(threads, frames.frameCount);
  std::vector<FrameCostEvaluator> evaluators(workers, FrameCostEvaluator(bvh, cost));
  std::vector<std::vector<Aabb>> boxes(workers, std::vector<Aabb>(frames.primCount));
  parallelFor(frames.frameCount, workers, [&](std::size_t f, unsigned w) {
    frames.fill(uint32_t(f), boxes[w]);
    costs[f] = evaluators[w].cost(boxes[w]);
  });
  return costs;
}

std::vector<MethodResult> compareMethods(std::span<const MethodSpec> methods, const PrimitiveBoxes& rep,
                                         const FrameSource& evaluation, const BaselineConfig& config) {
  checkFrames(rep);
  if (evaluation.primCount != rep.primCount)
    throw std::invalid_argument("evaluation frames and representative frames differ in primitive count");
  ProgressSink progress(config);
  std::vector<MethodResult> results(methods.size());
  std::vector<Bvh> trees(methods.size());
  const unsigned workers = workerCount(config.threads, evaluation.frameCount);

  for (std::size_t m = 0; m < methods.size(); ++m) {
    MethodResult& result = results[m];
    result.name = methods[m].name();
    const auto start = Clock::now();
    if (methods[m].method != Method::SahRebuild) {
      trees[m] = buildMethod(methods[m], rep, config);
      result.buildSeconds = secondsSince(start);
      continue;
    }
    // SAH-rebuild: an optimized tree for every evaluation frame, measured on that frame only.
    result.perFrame.assign(evaluation.frameCount, 0.0);
    std::vector<std::vector<Aabb>> boxes(workers, std::vector<Aabb>(evaluation.primCount));
    std::atomic<uint32_t> done{0};
    parallelFor(evaluation.frameCount, workers, [&](std::size_t f, unsigned w) {
      evaluation.fill(uint32_t(f), boxes[w]);
      const Bvh tree = buildOptimizedSah(boxes[w], config, derivedSeed(config.optimizer.seed, 2, f));
      result.perFrame[f] = frameCost(tree, 0, config.cost);
      progress("rebuild: " + std::to_string(++done) + "/" + std::to_string(evaluation.frameCount) +
               " frames");
    });
    result.buildSeconds = secondsSince(start);
  }

  // Every single-tree method on every evaluation frame, computing each frame's boxes once.
  std::vector<std::size_t> single;
  for (std::size_t m = 0; m < methods.size(); ++m)
    if (methods[m].method != Method::SahRebuild) {
      single.push_back(m);
      results[m].perFrame.assign(evaluation.frameCount, 0.0);
    }
  if (!single.empty()) {
    std::vector<std::vector<FrameCostEvaluator>> evaluators(workers);
    for (auto& perWorker : evaluators)
      for (std::size_t m : single) perWorker.emplace_back(trees[m], config.cost);
    std::vector<std::vector<Aabb>> boxes(workers, std::vector<Aabb>(evaluation.primCount));
    parallelFor(evaluation.frameCount, workers, [&](std::size_t f, unsigned w) {
      evaluation.fill(uint32_t(f), boxes[w]);
      for (std::size_t i = 0; i < single.size(); ++i)
        results[single[i]].perFrame[f] = evaluators[w][i].cost(boxes[w]);
    });
  }
  for (MethodResult& result : results) {
    if (result.perFrame.empty()) continue;
    double sum = 0.0, largest = 0.0;
    for (double c : result.perFrame) {
      sum += c;
      largest = std::max(largest, c);
    }
    result.average = sum / double(result.perFrame.size());
    result.maximum = largest;
  }
  return results;
}

}  // namespace tsah
