#include "tsah/optimize/segmentation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <thread>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"

namespace tsah {

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string timeText(double t) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", t);
  return buf;
}

// Seed of the per-frame optimized SAH tree of evaluation frame f (reference and last-resort parts).
uint64_t frameSeed(const SegmentationConfig& c, uint32_t f) { return c.baseline.optimizer.seed + 7919ull * (f + 1); }

// The search state: evaluation frames, the cache of candidate parts (tree + costs), objectives.
class Search {
 public:
  struct Candidate {
    TimeRange build;
    std::string method;         // the configured method's name, or "sah-frame" (see useFrameTree)
    Bvh tree;
    double buildSeconds = 0.0;
    InsertionOptimizer::Result optimization;
    uint32_t firstFrame = 0;    // costs[i] is the cost at evaluation frame firstFrame + i
    std::vector<double> costs;  // every evaluation frame inside the part (ends included)
  };

  Search(const Timeline& timeline, const SegmentationConfig& config)
      : timeline_(timeline), config_(config),
        times_(Timeline::uniformTimes(timeline.start, timeline.end, config.evaluationFrames)) {}

  const std::vector<double>& times() const { return times_; }
  std::size_t built() const { return built_; }

  // From now on the part starting at evaluation frame `frame` uses a per-frame optimized SAH tree
  // of that frame (the reference's tree when the reference covers every frame): the budget's last
  // resort for a part too short to split further.
  void useFrameTree(const TimeRange& part, uint32_t frame) {
    cache_.erase({part.start, part.end});
    frameTrees_[{part.start, part.end}] = frame;
  }

  // The part's tree, built once (a part is identified by its range; the build range follows).
  const Candidate& candidate(const TimeRange& part) {
    const auto key = std::make_pair(part.start, part.end);
    if (auto it = cache_.find(key); it == cache_.end()) {
      throwIfCancelled(config_.baseline.optimizer);  // SAH0 parts run no optimizer to ask
      if (config_.dealer) {
        prefetch(std::span<const TimeRange>(&part, 1));
      } else {
        if (config_.baseline.progress)
          config_.baseline.progress("tree " + std::to_string(cache_.size() + 1) + " for t " + timeText(part.start) +
                                    " .. " + timeText(part.end));
        cache_.emplace(key, build(part, config_.baseline));
        ++built_;
      }
    }
    return cache_.at(key);
  }

  // True when building several candidates at once saves time: more than one worker in all.
  bool speculates() const { return config_.dealer && config_.dealer->totalWorkers() > 1; }
  unsigned workers() const { return config_.dealer ? config_.dealer->totalWorkers() : 1; }

  // Builds the trees of the parts not in the cache yet, dealt to the dealer's workers (nothing
  // without a dealer: candidate() builds on demand).
  void prefetch(std::span<const TimeRange> parts) {
    if (!config_.dealer) return;
    std::vector<TimeRange> missing;
    for (const TimeRange& p : parts)
      if (!cache_.count({p.start, p.end}) &&
          std::none_of(missing.begin(), missing.end(), [&](const TimeRange& m) { return m.start == p.start && m.end == p.end; }))
        missing.push_back(p);
    if (missing.empty()) return;
    throwIfCancelled(config_.baseline.optimizer);
    if (config_.baseline.progress)
      config_.baseline.progress(std::to_string(missing.size()) + " trees from tree " + std::to_string(built_ + 1));
    // The workers' optimizer progress comes from several threads: one message at a time.
    std::mutex progressLock;
    BaselineConfig worker = config_.baseline;
    if (worker.progress)
      worker.progress = [&](const std::string& m) {
        const std::lock_guard lock(progressLock);
        config_.baseline.progress(m);
      };
    const std::vector<uint32_t> units = unitRange(0, uint32_t(missing.size()));
    const std::vector<UnitResult> results = config_.dealer->deal(
        units, [&](uint32_t unit, unsigned) { return encode(build(missing[unit], worker)); });
    for (std::size_t i = 0; i < missing.size(); ++i)
      cache_.emplace(std::make_pair(missing[i].start, missing[i].end), decode(results[i], missing[i]));
    built_ += missing.size();
  }

  // Cost at every evaluation frame, each with the tree of its part.
  std::vector<double> costs(std::span<const TimeRange> parts) {
    prefetch(parts);
    std::vector<double> out(times_.size());
    for (uint32_t f = 0; f < times_.size(); ++f) {
      const Candidate& c = candidate(parts[treeIndexAt(parts, times_[f])]);
      out[f] = c.costs.at(f - c.firstFrame);
    }
    return out;
  }

 private:
  // What a part's tree is built for: the part widened by half the overlap on its inner sides.
  TimeRange buildRange(const TimeRange& part) const {
    const double half = 0.5 * config_.overlap;
    return {part.start == timeline_.start ? part.start : std::max(timeline_.start, part.start - half),
            part.end == timeline_.end ? part.end : std::min(timeline_.end, part.end + half)};
  }

  // The part's tree and its costs at the evaluation frames inside it. Reads the search state but
  // changes nothing, so that workers may run it at once.
  Candidate build(const TimeRange& part, const BaselineConfig& baseline) const {
    Candidate c;
    c.build = buildRange(part);
    const auto start = std::chrono::steady_clock::now();
    if (auto frame = frameTrees_.find({part.start, part.end}); frame != frameTrees_.end()) {
      std::vector<Aabb> boxes(timeline_.primCount);
      timeline_.boxesAt(times_[frame->second], boxes);
      c.tree = buildOptimizedSah(boxes, baseline, frameSeed(config_, frame->second));
      c.method = "sah-frame";
    } else {
      const std::vector<double> repTimes =
          Timeline::uniformTimes(c.build.start, c.build.end, config_.representativeFrames);
      c.tree = buildMethod(config_.method, timeline_.sample(repTimes), baseline, &c.optimization);
      c.method = config_.method.method == Method::TSah ? "tsah" : config_.method.name();
    }
    c.buildSeconds = secondsSince(start);
    std::vector<double> inside;
    for (uint32_t f = 0; f < times_.size(); ++f)
      if (times_[f] >= part.start && times_[f] <= part.end) {
        if (inside.empty()) c.firstFrame = f;
        inside.push_back(times_[f]);
      }
    if (!inside.empty())
      c.costs = evaluateFrames(c.tree, timeline_.frames(std::move(inside)), baseline.objective.cost, baseline.threads);
    return c;
  }

  // A candidate as bytes for the dealer (the build range follows from the part).
  static UnitResult encode(const Candidate& c) {
    ByteWriter w;
    auto writeVector = [&w](const auto& v) {
      w.write(uint64_t(v.size()));
      w.writeArray(std::span(v));
    };
    w.write(uint64_t(c.method.size()));
    w.append(c.method.data(), c.method.size());
    w.write(c.tree.frameCount);
    w.write(c.tree.root);
    writeVector(c.tree.nodes);
    writeVector(c.tree.primIds);
    writeVector(c.tree.boxes);
    w.write(c.buildSeconds);
    const InsertionOptimizer::Result& o = c.optimization;
    writeVector(o.initialFrameCosts);
    writeVector(o.finalFrameCosts);
    w.write(o.initialCost);
    w.write(o.finalCost);
    writeVector(o.history);
    w.write(o.steps);
    w.write(o.acceptedSteps);
    w.write(o.seconds);
    w.write(uint8_t(o.timeLimitReached));
    w.write(c.firstFrame);
    writeVector(c.costs);
    return std::move(w.buffer());
  }

  Candidate decode(const UnitResult& bytes, const TimeRange& part) const {
    ByteReader r(bytes, "candidate tree");
    auto readVector = [&r](auto& v, const char* what) { r.readArray(v, r.read<uint64_t>(what), what); };
    Candidate c;
    std::vector<char> method;
    readVector(method, "method");
    c.method.assign(method.begin(), method.end());
    c.tree.frameCount = r.read<uint32_t>("frame count");
    c.tree.root = r.read<uint32_t>("root");
    readVector(c.tree.nodes, "nodes");
    readVector(c.tree.primIds, "primitive ids");
    readVector(c.tree.boxes, "boxes");
    c.buildSeconds = r.read<double>("build seconds");
    InsertionOptimizer::Result& o = c.optimization;
    readVector(o.initialFrameCosts, "initial frame costs");
    readVector(o.finalFrameCosts, "final frame costs");
    o.initialCost = r.read<double>("initial cost");
    o.finalCost = r.read<double>("final cost");
    readVector(o.history, "history");
    o.steps = r.read<uint64_t>("steps");
    o.acceptedSteps = r.read<uint64_t>("accepted steps");
    o.seconds = r.read<double>("seconds");
    o.timeLimitReached = r.read<uint8_t>("time limit") != 0;
    c.firstFrame = r.read<uint32_t>("first frame");
    readVector(c.costs, "costs");
    c.build = buildRange(part);
    return c;
  }

  const Timeline& timeline_;
  const SegmentationConfig& config_;
  std::vector<double> times_;
  std::map<std::pair<double, double>, Candidate> cache_;
  std::map<std::pair<double, double>, uint32_t> frameTrees_;
  std::size_t built_ = 0;
};

using SplitObjective = std::function<double(std::span<const double> costs)>;

std::vector<TimeRange> partsFromBoundaries(const Timeline& tl, std::span<const double> boundaries) {
  std::vector<TimeRange> parts;
  double start = tl.start;
  for (double b : boundaries) {
    parts.push_back({start, b});
    start = b;
  }
  parts.push_back({start, tl.end});
  return parts;
}

// Local search over the split points: each boundary moves along `positions` (sorted candidate
// times strictly inside the range) by a step that halves down to 1; a move is kept only when it
// lowers the objective, so the result is never worse than the start.
std::vector<TimeRange> localSearch(Search& search, const Timeline& tl, std::vector<double> boundaries,
                                   std::vector<double> positions, const SplitObjective& objective, uint32_t maxPasses,
                                   double minLength) {
  if (boundaries.empty()) return partsFromBoundaries(tl, boundaries);
  positions.insert(positions.end(), boundaries.begin(), boundaries.end());
  std::sort(positions.begin(), positions.end());
  positions.erase(std::unique(positions.begin(), positions.end()), positions.end());
  std::vector<std::size_t> at;  // boundary -> index into positions
  for (double b : boundaries) at.push_back(std::lower_bound(positions.begin(), positions.end(), b) - positions.begin());
  auto boundariesAt = [&](const std::vector<std::size_t>& idx) {
    std::vector<double> b;
    for (std::size_t i : idx) b.push_back(positions[i]);
    return b;
  };
  auto evaluate = [&](const std::vector<std::size_t>& idx) {
    return objective(search.costs(partsFromBoundaries(tl, boundariesAt(idx))));
  };
  double best = evaluate(at);
  const std::size_t firstStep = std::max<std::size_t>(1, positions.size() / (4 * (at.size() + 1)));
  for (uint32_t pass = 0; pass < maxPasses; ++pass) {
    bool improved = false;
    for (std::size_t step = firstStep;; step /= 2) {
      for (std::size_t s = 0; s < at.size(); ++s) {
        // The allowed moves of boundary s, tried in this order (down first).
        std::vector<std::vector<std::size_t>> trials;
        for (int dir : {-1, +1}) {
          if (dir < 0 && at[s] < step) continue;
          const std::size_t moved = dir < 0 ? at[s] - step : at[s] + step;
          if (moved >= positions.size()) continue;
          if ((s > 0 && moved <= at[s - 1]) || (s + 1 < at.size() && moved >= at[s + 1])) continue;
          const double before = s > 0 ? positions[at[s - 1]] : tl.start;
          const double after = s + 1 < at.size() ? positions[at[s + 1]] : tl.end;
          if (positions[moved] - before < minLength || after - positions[moved] < minLength) continue;
          trials.push_back(at);
          trials.back()[s] = moved;
        }
        if (search.speculates() && trials.size() > 1) {  // both moves' trees at once
          std::vector<TimeRange> parts;
          for (const auto& trial : trials)
            for (const TimeRange& p : partsFromBoundaries(tl, boundariesAt(trial))) parts.push_back(p);
          search.prefetch(parts);
        }
        for (const std::vector<std::size_t>& trial : trials) {
          const double value = evaluate(trial);
          if (value < best - 1e-12 * std::abs(best)) {
            best = value;
            at = trial;
            improved = true;
            break;
          }
        }
      }
      if (step == 1) break;
    }
    if (!improved) break;
  }
  return partsFromBoundaries(tl, boundariesAt(at));
}

void checkConfig(const Timeline& tl, const SegmentationConfig& c) {
  if (c.method.method == Method::SahRebuild)
    throw tsah::ConfigError("segmentation: SAH-rebuild builds a tree per frame, not one per part");
  if (!(tl.end > tl.start)) throw tsah::DataError("segmentation needs an animation (a time range of length > 0)");
  if (c.evaluationFrames < 2) throw tsah::ConfigError("segmentation needs at least 2 evaluation frames");
  if (c.representativeFrames < 1) throw tsah::ConfigError("segmentation needs at least 1 representative frame");
  if (!(c.overlap >= 0) || !std::isfinite(c.overlap)) throw tsah::ConfigError("the overlap must be >= 0");
  if (!tl.boxesAt) throw tsah::DataError("segmentation: the timeline has no boxes");
}

// The per-frame optimized SAH cost at every evaluation frame: built on a uniform sample of them,
// linear in between.
std::vector<double> referenceCosts(const Timeline& tl, const SegmentationConfig& c, std::span<const double> times) {
  const uint32_t m = static_cast<uint32_t>(times.size());
  if (!c.referenceCosts.empty()) {
    if (c.referenceCosts.size() != m)
      throw tsah::ConfigError("segmentation: " + std::to_string(c.referenceCosts.size()) + " reference costs for " +
                              std::to_string(m) + " evaluation frames");
    return c.referenceCosts;
  }
  const uint32_t r = c.referenceFrames == 0 || c.referenceFrames >= m ? m : std::max(2u, c.referenceFrames);
  std::vector<uint32_t> sample(r);
  for (uint32_t q = 0; q < r; ++q) sample[q] = static_cast<uint32_t>(std::lround(double(q) * (m - 1) / (r - 1)));
  // One tree per sampled frame, each on one thread: on this process's threads, or dealt to the
  // dealer's workers where they are GPUs (the device optimizer) or other processes.
  const unsigned hardware = std::max(1u, std::thread::hardware_concurrency());
  ThreadDealer threads(std::min<unsigned>(r, c.baseline.threads == 0 ? hardware : c.baseline.threads));
  const bool spread =
      c.dealer && (c.baseline.deviceOptimizer || c.dealer->totalWorkers() > c.dealer->localWorkers());
  WorkDealer& dealer = spread ? *c.dealer : threads;
  BaselineConfig single = c.baseline;
  single.threads = 1;
  single.progress = nullptr;
  const std::vector<UnitResult> results =
      dealer.deal(unitRange(0, r), [&](uint32_t q, unsigned) {
        std::vector<Aabb> boxes(tl.primCount);
        tl.boxesAt(times[sample[q]], boxes);
        const Bvh tree = buildOptimizedSah(boxes, single, frameSeed(c, sample[q]));
        PrimitiveBoxes one{1, tl.primCount, std::move(boxes)};
        const double cost = evaluateFrames(tree, FrameSource::fromBoxes(one), c.baseline.objective.cost, 1).front();
        UnitResult bytes(sizeof cost);
        std::memcpy(bytes.data(), &cost, sizeof cost);
        return bytes;
      });
  std::vector<double> sampled(r);
  for (uint32_t q = 0; q < r; ++q) std::memcpy(&sampled[q], results[q].data(), sizeof(double));
  std::vector<double> out(m);
  for (uint32_t q = 0; q + 1 < r; ++q)
    for (uint32_t f = sample[q]; f <= sample[q + 1]; ++f) {
      const double span = double(sample[q + 1] - sample[q]);
      const double a = span > 0 ? double(f - sample[q]) / span : 0.0;
      out[f] = (1.0 - a) * sampled[q] + a * sampled[q + 1];
    }
  return out;
}

SegmentationResult collect(Search& search, std::vector<TimeRange> parts) {
  SegmentationResult r;
  r.times = search.times();
  r.costs = search.costs(parts);
  for (const TimeRange& p : parts) {
    const Search::Candidate& c = search.candidate(p);
    r.buildRanges.push_back(c.build);
    r.methods.push_back(c.method);
    r.trees.push_back(c.tree);
    r.buildSeconds.push_back(c.buildSeconds);
    r.optimizations.push_back(c.optimization);
  }
  r.parts = std::move(parts);
  for (double c : r.costs) {
    r.average += c / double(r.costs.size());
    r.maximum = std::max(r.maximum, c);
  }
  r.treesBuilt = static_cast<uint32_t>(search.built());
  return r;
}

// The parts from `from` to the evaluation frames the binary search over [good, bad) tests next,
// level by level (its next test, then both possible tests after it, ...), one per worker.
void prefetchBisection(Search& search, double from, uint32_t good, uint32_t bad) {
  const std::vector<double>& t = search.times();
  std::vector<TimeRange> parts;
  std::vector<std::pair<uint32_t, uint32_t>> queue{{good, bad}};
  for (std::size_t q = 0; q < queue.size() && parts.size() < search.workers(); ++q) {
    const auto [g, b] = queue[q];
    if (b - g <= 1) continue;
    const uint32_t mid = g + (b - g) / 2;
    parts.push_back({from, t[mid]});
    queue.push_back({mid, b});  // it fits: the search goes on above mid
    queue.push_back({g, mid});
  }
  search.prefetch(parts);
}

// Budget mode, greedy: from each part's start, the farthest evaluation frame such that the part's
// tree keeps every frame it serves within the bound (binary search, assuming that a longer part
// never fits better). A part of one evaluation interval whose tree misses the bound gets a
// per-frame optimized tree of its frame; the last interval is split in its middle if needed, so
// that each of its two frames can get one. Parts are at least `minLength` long (the overlap).
std::vector<double> greedyBudgetBoundaries(Search& search, std::span<const double> bound, uint32_t maxTrees,
                                           double minLength) {
  const std::vector<double>& t = search.times();
  const uint32_t last = static_cast<uint32_t>(t.size() - 1);
  auto fits = [&](const TimeRange& part) {
    const Search::Candidate& c = search.candidate(part);
    for (uint32_t f = c.firstFrame; f < c.firstFrame + c.costs.size(); ++f) {
      const bool served = t[f] < part.end || f == last;  // a frame on the end belongs to the next part
      if (served && c.costs[f - c.firstFrame] > bound[f]) return false;
    }
    return true;
  };
  auto fitsOrFrameTree = [&](const TimeRange& part, uint32_t frame) {
    if (!fits(part)) search.useFrameTree(part, frame);
  };
  std::vector<double> boundaries;
  uint32_t i = 0;
  while (boundaries.size() + 1 < maxTrees && !fits({t[i], t[last]})) {
    uint32_t good = i + 1, bad = last;  // the boundary j lies in [good, bad)
    while (good < last && t[good] - t[i] < minLength) ++good;
    while (bad > good && t[last] - t[bad - 1] < minLength) --bad;
    if (good >= bad) break;  // no room for a boundary: the rest is one part
    if (good == i + 1) fitsOrFrameTree({t[i], t[good]}, i);
    while (bad - good > 1) {
      if (search.speculates()) prefetchBisection(search, t[i], good, bad);
      const uint32_t mid = good + (bad - good) / 2;
      if (fits({t[i], t[mid]}))
        good = mid;
      else
        bad = mid;
    }
    boundaries.push_back(t[good]);
    i = good;
  }
  const double middle = 0.5 * (t[i] + t[last]);
  if (i + 1 == last && boundaries.size() + 2 <= maxTrees && middle - t[i] >= minLength && !fits({t[i], t[last]})) {
    boundaries.push_back(middle);
    fitsOrFrameTree({t[i], middle}, i);
    fitsOrFrameTree({middle, t[last]}, last);
  }
  return boundaries;
}

}  // namespace

Timeline Timeline::fromTriangles(std::span<const uint32_t> indices, uint32_t vertexCount, double start, double end,
                                 std::function<void(double, std::span<float>)> positionsAt) {
  Timeline t;
  t.start = start;
  t.end = end;
  t.primCount = static_cast<uint32_t>(indices.size() / 3);
  t.boxesAt = [indices, vertexCount, positionsAt = std::move(positionsAt)](double time, std::span<Aabb> out) {
    std::vector<float> positions(std::size_t(vertexCount) * 3);
    positionsAt(time, positions);
    triangleBoxes(indices, positions, out);
  };
  return t;
}

std::vector<double> Timeline::uniformTimes(double a, double b, uint32_t n) {
  std::vector<double> t(n);
  for (uint32_t i = 0; i < n; ++i) t[i] = n == 1 ? a : a + (b - a) * double(i) / double(n - 1);
  if (n > 1) t.back() = b;
  return t;
}

PrimitiveBoxes Timeline::sample(std::span<const double> times) const {
  PrimitiveBoxes p;
  p.frameCount = static_cast<uint32_t>(times.size());
  p.primCount = primCount;
  p.boxes.resize(std::size_t(p.frameCount) * primCount);
  for (uint32_t f = 0; f < p.frameCount; ++f)
    boxesAt(times[f], std::span<Aabb>(p.boxes).subspan(std::size_t(f) * primCount, primCount));
  return p;
}

FrameSource Timeline::frames(std::vector<double> times) const {
  FrameSource source;
  source.frameCount = static_cast<uint32_t>(times.size());
  source.primCount = primCount;
  source.fill = [fill = boxesAt, times = std::move(times)](uint32_t frame, std::span<Aabb> out) {
    fill(times[frame], out);
  };
  return source;
}

SegmentationResult evaluateParts(const Timeline& timeline, std::span<const TimeRange> parts,
                                 const SegmentationConfig& config) {
  checkConfig(timeline, config);
  if (auto problem = validateTimeRanges(parts)) throw tsah::ConfigError("segmentation: " + *problem);
  const auto start = std::chrono::steady_clock::now();
  Search search(timeline, config);
  SegmentationResult r = collect(search, std::vector<TimeRange>(parts.begin(), parts.end()));
  r.searchSeconds = secondsSince(start);
  return r;
}

SegmentationResult segmentTimeline(const Timeline& timeline, const SegmentationConfig& config) {
  checkConfig(timeline, config);
  const auto start = std::chrono::steady_clock::now();
  Search search(timeline, config);
  const std::vector<double>& t = search.times();
  const std::vector<double> interior(t.begin() + 1, t.end() - 1);

  if (config.mode == SegmentationConfig::Mode::Count) {
    if (config.count == 0) throw tsah::ConfigError("segmentation: the number of trees must be at least 1");
    std::vector<double> boundaries;
    for (const TimeRange& p : equalTimeRanges(timeline.start, timeline.end, config.count))
      if (p.start > timeline.start) boundaries.push_back(p.start);
    if (config.count > 1 && (timeline.end - timeline.start) / config.count < config.overlap)
      throw tsah::ConfigError("segmentation: the overlap is longer than an equal-time part");
    const bool peak = config.method.k > 0;
    const SplitObjective objective = [peak](std::span<const double> c) {
      double sum = 0.0, top = 0.0;
      for (double x : c) {
        sum += x;
        top = std::max(top, x);
      }
      return peak ? top : sum / double(c.size());
    };
    std::vector<TimeRange> parts = localSearch(search, timeline, boundaries, interior, objective, config.maxPasses,
                                               config.overlap);
    SegmentationResult r = collect(search, std::move(parts));
    r.searchSeconds = secondsSince(start);
    return r;
  }

  if (!(config.budget > 0) || !std::isfinite(config.budget))
    throw tsah::ConfigError("segmentation: the budget must be a positive number");
  if (config.maxTrees == 0) throw tsah::ConfigError("segmentation: maxTrees must be at least 1");
  std::vector<double> reference, bound(t.size(), config.budget);
  double referenceSeconds = 0.0;
  if (config.budgetRelative) {
    if (config.baseline.progress) config.baseline.progress("reference: per-frame optimized SAH trees");
    const auto refStart = std::chrono::steady_clock::now();
    reference = referenceCosts(timeline, config, t);
    referenceSeconds = secondsSince(refStart);
    for (std::size_t f = 0; f < t.size(); ++f) bound[f] = config.budget * reference[f];
  }
  const std::vector<double> boundaries = greedyBudgetBoundaries(search, bound, config.maxTrees, config.overlap);
  std::vector<TimeRange> parts = partsFromBoundaries(timeline, boundaries);
  if (config.refine && !boundaries.empty()) {
    // Same count, the worst cost/bound ratio lowered: a feasible start stays feasible.
    const SplitObjective worstRatio = [&bound](std::span<const double> c) {
      double top = 0.0;
      for (std::size_t f = 0; f < c.size(); ++f) top = std::max(top, c[f] / bound[f]);
      return top;
    };
    parts = localSearch(search, timeline, boundaries, interior, worstRatio, config.maxPasses, config.overlap);
  }
  SegmentationResult r = collect(search, std::move(parts));
  r.reference = std::move(reference);
  r.bound = std::move(bound);
  r.budgetMet = true;
  for (std::size_t f = 0; f < t.size(); ++f) r.budgetMet = r.budgetMet && r.costs[f] <= r.bound[f];
  r.referenceSeconds = referenceSeconds;
  r.searchSeconds = secondsSince(start);
  return r;
}

}  // namespace tsah
