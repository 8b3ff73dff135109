#include "tsah/optimize/baselines.hpp"

#include <algorithm>
#include <atomic>
#include <ctime>
#include <exception>
#include <limits>
#include <mutex>
#include <thread>
#include <tuple>
#include <utility>

#include "tsah/base/error.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/build/sah_builder.hpp"

namespace tsah {

namespace {

// CPU time of the calling thread: what a task costs on one core, whatever else shares the machine.
double threadCpuSeconds() {
  timespec t{};
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t) != 0) return 0.0;
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
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
  if (config.objective.maxLeafSize <= 1) return bvh;
  return LeafCollapser(Objective{k, config.objective.cost, config.objective.maxLeafSize}).collapse(bvh);
}

// An optimization followed by collapseLeaves, the collapse done by the optimizer from its own
// storage (the same tree; the optimized tree's boxes of every frame are never copied).
InsertionOptimizer::Result optimizeAndCollapse(Bvh bvh, const PrimitiveBoxes& prims,
                                               const InsertionOptimizer::Config& settings,
                                               const BaselineConfig& config) {
  if (config.objective.maxLeafSize <= 1) return optimizeTree(std::move(bvh), prims, settings, config);
  const LeafCollapser collapser(Objective{settings.k, config.objective.cost, config.objective.maxLeafSize});
  return optimizeTree(std::move(bvh), prims, settings, config, &collapser);
}

InsertionOptimizer::Config optimizerConfig(const BaselineConfig& config, int k, uint64_t seed) {
  InsertionOptimizer::Config c = config.optimizer;
  c.cost = config.objective.cost;
  c.k = k;
  c.seed = seed;
  c.progress = nullptr;
  return c;
}

void checkFrames(const PrimitiveBoxes& rep) {
  if (rep.frameCount == 0) throw tsah::DataError("no representative frames");
  if (rep.boxes.size() != std::size_t(rep.frameCount) * rep.primCount)
    throw tsah::DataError("representative frame boxes do not match frames x primitives");
}

}  // namespace

InsertionOptimizer::Result optimizeTree(Bvh bvh, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& settings,
                                        const BaselineConfig& config, const LeafCollapser* collapse) {
  if (config.deviceOptimizer) return config.deviceOptimizer(std::move(bvh), prims, settings, collapse);
  if (config.optimizerKind == OptimizerKind::Sequential)
    return InsertionOptimizer(settings).optimize(std::move(bvh), prims, collapse);
  return ParallelReinsertionOptimizer(settings, config.parallel).optimize(std::move(bvh), prims, collapse);
}

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
  return method == Method::TSah ? "tsah" + std::to_string(k) : tsah::name(method);
}

MethodSpec MethodSpec::parse(const std::string& name) {
  if (name.rfind("tsah", 0) == 0 && name.size() > 4 && name.size() <= 6 &&
      std::all_of(name.begin() + 4, name.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    const int k = std::stoi(name.substr(4));
    if (k > Objective::kMaxK)
      throw ConfigError("method '" + name + "': the T-SAH exponent k must be in 0.." + std::to_string(Objective::kMaxK));
    return {Method::TSah, k};
  }
  try {
    return {tsah::parse<Method>(name), 0};
  } catch (const ConfigError&) {
    throw ConfigError("unknown method '" + name + "' (expected sah0, sahstar, rebuild or tsah<k> such as tsah0, tsah2)");
  }
}

namespace {

// The tree every method starts from: one primitive per leaf, by the sweep SAH builder (the paper's),
// or the multithreaded binned one when the configuration asks for it.
Bvh initialTree(std::span<const Aabb> frame, const BaselineConfig& config) {
  if (!config.binnedInitialTree) return SweepSahBuilder({config.objective.cost, 1}).build(frame);
  BinnedSahBuilder::Config binned;
  binned.cost = config.objective.cost;
  binned.maxLeafSize = 1;
  return BinnedSahBuilder(binned).build(frame);
}

}  // namespace

Bvh buildSah0(const PrimitiveBoxes& rep, const BaselineConfig& config) {
  checkFrames(rep);
  Bvh bvh = initialTree(rep.frame(0), config);
  bvh = collapseLeaves(bvh, config, 0);  // with the cost of frame 0, the only frame SAH0 knows
  refit(bvh, rep);
  return bvh;
}

Bvh buildOptimizedSah(std::span<const Aabb> frame, const BaselineConfig& config, uint64_t seed) {
  const PrimitiveBoxes boxes = singleFrame(frame);
  Bvh bvh = initialTree(frame, config);
  return optimizeAndCollapse(std::move(bvh), boxes, optimizerConfig(config, 0, seed), config).bvh;
}

namespace {

// One SAH* candidate: the optimized SAH tree of representative frame f, refitted to every
// representative frame, with its average cost over them.
std::pair<Bvh, double> sahStarCandidate(const PrimitiveBoxes& rep, uint32_t f, const BaselineConfig& config) {
  Bvh tree = buildOptimizedSah(rep.frame(f), config, derivedSeed(config.optimizer.seed, 1, f));
  refit(tree, rep);
  const double average = temporalCost(frameCosts(tree, config.objective.cost), 0);
  return {std::move(tree), average};
}

// The candidate with the lowest average (the first of equal ones).
std::size_t bestCandidate(const std::vector<double>& average) {
  return std::size_t(std::min_element(average.begin(), average.end()) - average.begin());
}

}  // namespace

Bvh buildSahStar(const PrimitiveBoxes& rep, const BaselineConfig& config) {
  checkFrames(rep);
  ProgressSink progress(config);
  std::vector<Bvh> trees(rep.frameCount);
  std::vector<double> average(rep.frameCount);
  std::atomic<uint32_t> done{0};
  parallelFor(rep.frameCount, workerCount(config.threads, rep.frameCount), [&](std::size_t f, unsigned) {
    std::tie(trees[f], average[f]) = sahStarCandidate(rep, uint32_t(f), config);
    progress("sahstar: " + std::to_string(++done) + "/" + std::to_string(rep.frameCount) + " frames");
  });
  return std::move(trees[bestCandidate(average)]);
}

Bvh buildTSah(const PrimitiveBoxes& rep, int k, const BaselineConfig& config,
              InsertionOptimizer::Result* details) {
  checkFrames(rep);
  ProgressSink progress(config);
  Bvh bvh = initialTree(rep.frame(0), config);
  InsertionOptimizer::Config oc = optimizerConfig(config, k, config.optimizer.seed);
  const std::string label = "tsah" + std::to_string(k);
  oc.progress = [&](const InsertionOptimizer::BatchRecord& r) {
    if (config.optimizer.progress) config.optimizer.progress(r);
    if (progress.active())
      progress(label + ": batch " + std::to_string(r.batch) + ", cost " + std::to_string(r.cost));
  };
  InsertionOptimizer::Result result = optimizeAndCollapse(std::move(bvh), rep, oc, config);
  Bvh collapsed = std::move(result.bvh);
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
  throw tsah::ConfigError("method " + method.name() + " builds one tree per frame, not one tree");
}

std::vector<double> evaluateFrames(const Bvh& bvh, const FrameSource& frames, const CostModel& cost,
                                   unsigned threads) {
  if (frames.primCount != bvh.primCount())
    throw tsah::DataError("evaluation frames hold " + std::to_string(frames.primCount) + " primitives, the tree " +
                          std::to_string(bvh.primCount()));
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
    throw tsah::DataError("evaluation frames and representative frames differ in primitive count");
  ProgressSink progress(config);
  // Workers report through the one sink above (one message at a time); per-batch optimizer
  // callbacks would come from several threads at once, so they are not forwarded here.
  BaselineConfig inner = config;
  inner.progress = [&progress](const std::string& message) { progress(message); };
  inner.optimizer.progress = nullptr;
  const std::size_t count = methods.size();
  std::vector<MethodResult> results(count);
  std::vector<Bvh> trees(count);
  std::vector<std::vector<Bvh>> candidates(count);         // SAH*: one tree per representative frame
  std::vector<std::vector<double>> candidateAverage(count);

  // Every independent piece of work is one task: a T-SAH or SAH0 tree, one SAH* candidate, one
  // SAH-rebuild frame. The longest (T-SAH) go first so the workers finish together.
  struct Task {
    std::size_t method;
    uint32_t index;
  };
  std::vector<Task> tasks;
  for (std::size_t m = 0; m < count; ++m) {
    results[m].name = methods[m].name();
    if (methods[m].method == Method::TSah) tasks.push_back({m, 0});
  }
  for (std::size_t m = 0; m < count; ++m) {
    switch (methods[m].method) {
      case Method::SahStar:
        candidates[m].resize(rep.frameCount);
        candidateAverage[m].resize(rep.frameCount);
        for (uint32_t f = 0; f < rep.frameCount; ++f) tasks.push_back({m, f});
        break;
      case Method::SahRebuild:
        results[m].perFrame.assign(evaluation.frameCount, 0.0);
        for (uint32_t f = 0; f < evaluation.frameCount; ++f) tasks.push_back({m, f});
        break;
      case Method::Sah0:
        tasks.push_back({m, 0});
        break;
      case Method::TSah:
        break;
    }
  }

  // Build time of a method: the sum of its tasks' CPU times, i.e. what one core would take.
  std::vector<double> taskSeconds(tasks.size(), 0.0);
  const unsigned workers = workerCount(config.threads, tasks.size());
  std::vector<std::vector<Aabb>> frameBoxes(workers, std::vector<Aabb>(evaluation.primCount));
  std::atomic<std::size_t> done{0};
  parallelFor(tasks.size(), workers, [&](std::size_t t, unsigned w) {
    const Task task = tasks[t];
    const MethodSpec& method = methods[task.method];
    const double start = threadCpuSeconds();
    switch (method.method) {
      case Method::Sah0:
      case Method::TSah:
        trees[task.method] = buildMethod(method, rep, inner);
        break;
      case Method::SahStar:
        std::tie(candidates[task.method][task.index], candidateAverage[task.method][task.index]) =
            sahStarCandidate(rep, task.index, inner);
        break;
      case Method::SahRebuild: {
        evaluation.fill(task.index, frameBoxes[w]);
        const Bvh tree =
            buildOptimizedSah(frameBoxes[w], inner, derivedSeed(config.optimizer.seed, 2, task.index));
        results[task.method].perFrame[task.index] = frameCost(tree, 0, config.objective.cost);
        break;
      }
    }
    taskSeconds[t] = threadCpuSeconds() - start;
    progress("built " + std::to_string(++done) + "/" + std::to_string(tasks.size()) + " trees (" +
             results[task.method].name + ")");
  });
  for (std::size_t t = 0; t < tasks.size(); ++t) results[tasks[t].method].buildSeconds += taskSeconds[t];
  for (std::size_t m = 0; m < count; ++m)
    if (methods[m].method == Method::SahStar)
      trees[m] = std::move(candidates[m][bestCandidate(candidateAverage[m])]);

  // Every single-tree method on every evaluation frame, computing each frame's boxes once.
  std::vector<std::size_t> single;
  for (std::size_t m = 0; m < count; ++m)
    if (methods[m].method != Method::SahRebuild) {
      single.push_back(m);
      results[m].perFrame.assign(evaluation.frameCount, 0.0);
    }
  if (!single.empty()) {
    const unsigned evalWorkers = workerCount(config.threads, evaluation.frameCount);
    std::vector<std::vector<FrameCostEvaluator>> evaluators(evalWorkers);
    for (auto& perWorker : evaluators)
      for (std::size_t m : single) perWorker.emplace_back(trees[m], config.objective.cost);
    frameBoxes.resize(std::max<std::size_t>(frameBoxes.size(), evalWorkers), std::vector<Aabb>(evaluation.primCount));
    progress("evaluating " + std::to_string(evaluation.frameCount) + " frames");
    parallelFor(evaluation.frameCount, evalWorkers, [&](std::size_t f, unsigned w) {
      evaluation.fill(uint32_t(f), frameBoxes[w]);
      for (std::size_t i = 0; i < single.size(); ++i)
        results[single[i]].perFrame[f] = evaluators[w][i].cost(frameBoxes[w]);
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
