#include "tsah/insertion_optimizer.hpp"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "random.hpp"

namespace tsah {

namespace {

inline bool sameBox(const Aabb& a, const Aabb& b) {
  return a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x &&
         a.hi.y == b.hi.y && a.hi.z == b.hi.z;
}

// Surface area of the union of two boxes, without building the union box first.
inline float unionArea(const Aabb& a, const Aabb& b) {
  const float dx = std::max(a.hi.x, b.hi.x) - std::min(a.lo.x, b.lo.x);
  const float dy = std::max(a.hi.y, b.hi.y) - std::min(a.lo.y, b.lo.y);
  const float dz = std::max(a.hi.z, b.hi.z) - std::min(a.lo.z, b.lo.z);
  return 2.0f * (dx * dy + dy * dz + dz * dx);
}

struct QueueEntry {
  float induced;
  uint32_t node;
};
// Min-heap on the induced cost (std heap algorithms build max-heaps).
inline bool laterInQueue(const QueueEntry& a, const QueueEntry& b) { return a.induced > b.induced; }

}  // namespace

struct InsertionSession::Impl {
  InsertionOptimizer::Config config;
  Bvh bvh;
  uint32_t frames = 1;

  // Per frame.
  std::vector<double> rootArea;    // S_i (constant: the root box is the union of all primitives)
  std::vector<double> innerArea;   // sum of interior node areas
  std::vector<double> leafArea;    // sum of leaf areas times primitive counts (constant)
  std::vector<double> frameCost;   // C_i
  std::vector<float> areaFactor;   // w_i / (W S_i): A(B) = sum_i areaFactor_i * area(B_i)
  std::vector<float> deltaFactor;  // w_i / W: Delta_N = sum_i deltaFactor_i * S_N(i)
  uint64_t innerCount = 0, primTotal = 0;
  double currentCost = 0.0;

  // Per node.
  std::vector<float> area;   // A(N)
  std::vector<float> delta;  // Delta_N (Metropolis-Hastings target, up to a constant)

  // Step state: undo log of every node touched, per-frame change of the interior area sum.
  struct Saved {
    uint32_t node;
    BvhNode data;
    float area, delta;
  };
  std::vector<Saved> undoLog;
  std::vector<Aabb> undoBoxes;
  std::vector<uint32_t> touchedInStep;
  uint32_t stepStamp = 0;
  uint32_t savedRoot = 0;
  std::vector<double> stepAreaChange;
  std::vector<double> candidateCost;
  std::vector<Aabb> scratchBoxes;
  std::vector<QueueEntry> queue;

  Rng rng;
  uint32_t chainNode = kInvalidIndex;  // last node accepted by the Metropolis-Hastings chain
  uint64_t steps = 0, accepted = 0;

  Impl(Bvh tree, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& cfg)
      : config(cfg), bvh(std::move(tree)), rng(cfg.seed) {
    if (config.k < 0) throw std::invalid_argument("InsertionOptimizer: the exponent k must be >= 0");
    if (prims.frameCount == 0) throw std::invalid_argument("InsertionOptimizer: no frames");
    if (prims.primCount != bvh.primCount())
      throw std::invalid_argument("InsertionOptimizer: the tree holds " +
                                  std::to_string(bvh.primCount()) + " primitives, the boxes " +
                                  std::to_string(prims.primCount));
    refit(bvh, prims);
    frames = prims.frameCount;
    rootArea.assign(frames, 0.0);
    innerArea.assign(frames, 0.0);
    leafArea.assign(frames, 0.0);
    frameCost.assign(frames, 0.0);
    areaFactor.assign(frames, 0.0f);
    deltaFactor.assign(frames, 0.0f);
    stepAreaChange.assign(frames, 0.0);
    candidateCost.assign(frames, 0.0);
    scratchBoxes.resize(frames);
    area.assign(bvh.nodes.size(), 0.0f);
    delta.assign(bvh.nodes.size(), 0.0f);
    touchedInStep.assign(bvh.nodes.size(), 0);
    for (const BvhNode& node : bvh.nodes) {
      if (node.isLeaf()) primTotal += node.primCount;
      else ++innerCount;
    }
    refresh(/*firstTime=*/true);
  }

  const Aabb* boxes(uint32_t n) const { return bvh.boxes.data() + std::size_t(n) * frames; }
  Aabb* boxes(uint32_t n) { return bvh.boxes.data() + std::size_t(n) * frames; }

  double costOf(std::span<const double> costs) const { return temporalCost(costs, config.k); }

  void computeFrameCost(uint32_t f) {
    frameCost[f] = rootArea[f] > 0.0
                       ? (config.cost.ct * innerArea[f] + config.cost.ci * leafArea[f]) / rootArea[f]
                       : double(config.cost.ct) * double(innerCount) +
                             double(config.cost.ci) * double(primTotal);
  }

  void updateNodeCaches(uint32_t n) {
    const Aabb* b = boxes(n);
    float a = 0.0f, d = 0.0f;
    for (uint32_t f = 0; f < frames; ++f) {
      const float s = b[f].area();
      a += areaFactor[f] * s;
      d += deltaFactor[f] * s;
    }
    area[n] = a;
    delta[n] = d;
  }

  void refresh(bool firstTime = false) {
    std::fill(innerArea.begin(), innerArea.end(), 0.0);
    std::fill(leafArea.begin(), leafArea.end(), 0.0);
    for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
      const BvhNode& node = bvh.nodes[n];
      const Aabb* b = boxes(n);
      if (node.isLeaf())
        for (uint32_t f = 0; f < frames; ++f) leafArea[f] += double(b[f].area()) * node.primCount;
      else
        for (uint32_t f = 0; f < frames; ++f) innerArea[f] += b[f].area();
    }
    for (uint32_t f = 0; f < frames; ++f) {
      rootArea[f] = boxes(bvh.root)[f].area();
      computeFrameCost(f);
    }
    currentCost = costOf(frameCost);
    // With k = 0 the weights never change: the cached areas stay valid.
    if (!firstTime && config.k == 0) return;
    const std::vector<double> w = temporalWeights(frameCost, config.k);
    for (uint32_t f = 0; f < frames; ++f) {
      deltaFactor[f] = float(w[f]);
      areaFactor[f] = rootArea[f] > 0.0 ? float(w[f] / rootArea[f]) : 0.0f;
    }
    for (uint32_t n = 0; n < bvh.nodeCount(); ++n) updateNodeCaches(n);
  }

  bool eligible(uint32_t n) const {
    if (n >= bvh.nodes.size()) return false;
    const BvhNode& node = bvh.nodes[n];
    return !node.isLeaf() && node.parent != kInvalidIndex && bvh.nodes[node.parent].parent != kInvalidIndex;
  }

  // ---- undo log ----
  void save(uint32_t n) {
    if (touchedInStep[n] == stepStamp) return;
    touchedInStep[n] = stepStamp;
    undoLog.push_back({n, bvh.nodes[n], area[n], delta[n]});
    const Aabb* b = boxes(n);
    undoBoxes.insert(undoBoxes.end(), b, b + frames);
  }

  void undo() {
    for (std::size_t e = 0; e < undoLog.size(); ++e) {
      const Saved& s = undoLog[e];
      bvh.nodes[s.node] = s.data;
      area[s.node] = s.area;
      delta[s.node] = s.delta;
      std::copy_n(undoBoxes.data() + e * frames, frames, boxes(s.node));
    }
    bvh.root = savedRoot;
  }

  void replaceChild(uint32_t parent, uint32_t oldChild, uint32_t newChild) {
    BvhNode& p = bvh.nodes[parent];
    if (p.left == oldChild) p.left = newChild;
    else p.right = newChild;
  }

  // Recomputes boxes from the children upwards, stopping at the first node whose boxes did not
  // change (its ancestors cannot change either); records the area change of every frame.
  void refitUpward(uint32_t n) {
    Aabb* fresh = scratchBoxes.data();
    while (n != kInvalidIndex) {
      const BvhNode& node = bvh.nodes[n];
      const Aabb* l = boxes(node.left);
      const Aabb* r = boxes(node.right);
      Aabb* b = boxes(n);
      bool changed = false;
      for (uint32_t f = 0; f < frames; ++f) {
        fresh[f] = merge(l[f], r[f]);
        changed |= !sameBox(fresh[f], b[f]);
      }
      if (!changed) return;
      save(n);
      float a = 0.0f, d = 0.0f;
      for (uint32_t f = 0; f < frames; ++f) {
        const float before = b[f].area(), after = fresh[f].area();
        stepAreaChange[f] += double(after) - double(before);
        b[f] = fresh[f];
        a += areaFactor[f] * after;
        d += deltaFactor[f] * after;
      }
      area[n] = a;
      delta[n] = d;
      n = node.parent;
    }
  }

  // Weighted multi-frame area of the union of node x's boxes and the given boxes.
  float unionCost(uint32_t x, const Aabb* c) const {
    const Aabb* b = boxes(x);
    float sum = 0.0f;
    for (uint32_t f = 0; f < frames; ++f) sum += areaFactor[f] * unionArea(b[f], c[f]);
    return sum;
  }

  // Branch-and-bound: the node X for which making c a sibling of X raises the cost least.
  uint32_t findBestSibling(uint32_t c) {
    const Aabb* cb = boxes(c);
    const float areaC = area[c];
    float best = std::numeric_limits<float>::infinity();
    uint32_t bestNode = bvh.root;
    queue.clear();
    queue.push_back({0.0f, bvh.root});
    while (!queue.empty()) {
      std::pop_heap(queue.begin(), queue.end(), laterInQueue);
      const QueueEntry top = queue.back();
      queue.pop_back();
      if (top.induced + areaC >= best) break;  // every entry left has at least this induced cost
      const uint32_t x = top.node;
      const float total = top.induced + unionCost(x, cb);
      if (total < best) {
        best = total;
        bestNode = x;
      }
      const BvhNode& node = bvh.nodes[x];
      if (node.isLeaf()) continue;
      const float induced = total - area[x];  // x grows by (union - A(x)) when c goes below it
      if (induced + areaC >= best) continue;
      queue.push_back({induced, node.left});
      std::push_heap(queue.begin(), queue.end(), laterInQueue);
      queue.push_back({induced, node.right});
      std::push_heap(queue.begin(), queue.end(), laterInQueue);
    }
    return bestNode;
  }

  // Makes the detached subtree c a child of the free node q, with the best sibling X in the tree.
  void insert(uint32_t c, uint32_t q) {
    const uint32_t x = findBestSibling(c);
    const uint32_t xp = bvh.nodes[x].parent;
    save(x);
    save(q);
    save(c);
    if (xp != kInvalidIndex) save(xp);
    BvhNode& node = bvh.nodes[q];
    node.parent = xp;
    node.left = x;
    node.right = c;
    node.primBegin = 0;
    node.primCount = 0;
    bvh.nodes[x].parent = q;
    bvh.nodes[c].parent = q;
    if (xp == kInvalidIndex) bvh.root = q;
    else replaceChild(xp, x, q);
    Aabb* b = boxes(q);
    const Aabb* xb = boxes(x);
    const Aabb* cb = boxes(c);
    for (uint32_t f = 0; f < frames; ++f) {
      b[f] = merge(xb[f], cb[f]);
      stepAreaChange[f] += b[f].area();
    }
    updateNodeCaches(q);
    refitUpward(xp);
  }

  bool step(uint32_t n) {
    if (!eligible(n)) throw std::invalid_argument("InsertionSession::step: node is not eligible");
    ++steps;
    ++stepStamp;
    if (stepStamp == 0) {  // wrapped: clear the stamps so no node looks touched
      std::fill(touchedInStep.begin(), touchedInStep.end(), 0);
      stepStamp = 1;
    }
    undoLog.clear();
    undoBoxes.clear();
    savedRoot = bvh.root;
    std::fill(stepAreaChange.begin(), stepAreaChange.end(), 0.0);

    const uint32_t p = bvh.nodes[n].parent;
    const uint32_t g = bvh.nodes[p].parent;
    const uint32_t s = bvh.nodes[p].left == n ? bvh.nodes[p].right : bvh.nodes[p].left;
    uint32_t first = bvh.nodes[n].left, second = bvh.nodes[n].right;
    for (uint32_t touched : {n, p, g, s, first, second}) save(touched);

    // Detach N and P: the sibling takes P's place, the interior areas of N and P leave the cost.
    for (uint32_t f = 0; f < frames; ++f)
      stepAreaChange[f] -= double(boxes(n)[f].area()) + double(boxes(p)[f].area());
    replaceChild(g, p, s);
    bvh.nodes[s].parent = g;
    refitUpward(g);

    // Reinsert N's children, the larger first, reusing N and P as their new parents.
    if (area[second] > area[first]) std::swap(first, second);
    bvh.nodes[first].parent = kInvalidIndex;
    bvh.nodes[second].parent = kInvalidIndex;
    insert(first, n);
    insert(second, p);

    for (uint32_t f = 0; f < frames; ++f)
      candidateCost[f] = rootArea[f] > 0.0
                             ? frameCost[f] + config.cost.ct * stepAreaChange[f] / rootArea[f]
                             : frameCost[f];
    const double newCost = costOf(candidateCost);
    if (newCost > currentCost) {
      undo();
      return false;
    }
    frameCost.swap(candidateCost);
    for (uint32_t f = 0; f < frames; ++f) innerArea[f] += stepAreaChange[f];
    currentCost = newCost;
    ++accepted;
    return true;
  }

  // Uniform over eligible nodes by rejection; a scan from a random start when they are rare.
  uint32_t uniformEligible() {
    const auto count = static_cast<uint32_t>(bvh.nodes.size());
    if (count == 0) return kInvalidIndex;
    for (uint32_t attempt = 0; attempt < 64; ++attempt) {
      const uint32_t n = rng.below(count);
      if (eligible(n)) return n;
    }
    const uint32_t start = rng.below(count);
    for (uint32_t i = 0; i < count; ++i) {
      const uint32_t n = (start + i) % count;
      if (eligible(n)) return n;
    }
    return kInvalidIndex;
  }

  uint32_t selectMetropolisHastings() {
    if (chainNode == kInvalidIndex || chainNode >= bvh.nodes.size()) {
      chainNode = uniformEligible();
      return chainNode;
    }
    // Independent chain: propose uniformly, accept with min(1, Delta_new / Delta_current); go on
    // until a node other than the last accepted one is accepted (re-optimizing the same node
    // would find the same position again).
    const float current = delta[chainNode];
    const uint64_t limit = 64 * uint64_t(bvh.nodes.size()) + 4096;  // only tiny trees get near it
    uint32_t proposal = kInvalidIndex;
    for (uint64_t i = 0; i < limit; ++i) {
      proposal = uniformEligible();
      if (proposal == kInvalidIndex) return kInvalidIndex;
      const float d = delta[proposal];
      const bool accept = d >= current || rng.uniform() * double(current) < double(d);
      if (accept && proposal != chainNode) break;
    }
    chainNode = proposal;
    return proposal;
  }

  uint32_t selectNode() {
    switch (config.selection) {
      case InsertionOptimizer::Selection::MetropolisHastings:
        return selectMetropolisHastings();
      case InsertionOptimizer::Selection::Uniform:
      case InsertionOptimizer::Selection::BatchSort:
        return uniformEligible();
    }
    return kInvalidIndex;
  }

  std::vector<uint32_t> batchSortNodes(uint32_t count) const {
    struct Candidate {
      double measure;
      uint32_t node;
    };
    std::vector<Candidate> candidates;
    for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
      if (!eligible(n)) continue;
      const BvhNode& node = bvh.nodes[n];
      const double a = area[n];
      const double l = area[node.left], r = area[node.right];
      const double tiny = 1e-30;
      const double mSum = a / std::max(0.5 * (l + r), tiny);
      const double mMin = a / std::max(std::min(l, r), tiny);
      candidates.push_back({mSum * mMin * a, n});
    }
    const std::size_t take = std::min<std::size_t>(count, candidates.size());
    std::partial_sort(candidates.begin(), candidates.begin() + std::ptrdiff_t(take), candidates.end(),
                      [](const Candidate& x, const Candidate& y) {
                        return x.measure > y.measure || (x.measure == y.measure && x.node < y.node);
                      });
    std::vector<uint32_t> nodes(take);
    for (std::size_t i = 0; i < take; ++i) nodes[i] = candidates[i].node;
    return nodes;
  }
};

InsertionSession::InsertionSession(Bvh bvh, const PrimitiveBoxes& prims,
                                   const InsertionOptimizer::Config& config)
    : impl_(std::make_unique<Impl>(std::move(bvh), prims, config)) {}
InsertionSession::~InsertionSession() = default;
InsertionSession::InsertionSession(InsertionSession&&) noexcept = default;
InsertionSession& InsertionSession::operator=(InsertionSession&&) noexcept = default;

bool InsertionSession::eligible(uint32_t node) const { return impl_->eligible(node); }
bool InsertionSession::step(uint32_t node) { return impl_->step(node); }
uint32_t InsertionSession::selectNode() { return impl_->selectNode(); }
std::vector<uint32_t> InsertionSession::batchSortNodes(uint32_t count) const {
  return impl_->batchSortNodes(count);
}
void InsertionSession::refresh() { impl_->refresh(); }
double InsertionSession::cost() const { return impl_->currentCost; }
std::span<const double> InsertionSession::frameCosts() const { return impl_->frameCost; }
const Bvh& InsertionSession::bvh() const { return impl_->bvh; }
Bvh InsertionSession::release() { return std::move(impl_->bvh); }
uint64_t InsertionSession::steps() const { return impl_->steps; }
uint64_t InsertionSession::acceptedSteps() const { return impl_->accepted; }

InsertionOptimizer::InsertionOptimizer(Config config) : config_(std::move(config)) {
  if (config_.k < 0) throw std::invalid_argument("InsertionOptimizer: the exponent k must be >= 0");
  if (!(config_.batchFraction > 0.0) || config_.batchFraction > 1.0)
    throw std::invalid_argument("InsertionOptimizer: batchFraction must be in (0, 1]");
  if (config_.batchesWithoutImprovement == 0)
    throw std::invalid_argument("InsertionOptimizer: batchesWithoutImprovement must be >= 1");
}

InsertionOptimizer::Result InsertionOptimizer::optimize(Bvh bvh, const PrimitiveBoxes& prims) const {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  const auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  const bool limited = config_.timeLimitSeconds > 0.0;

  InsertionSession session(std::move(bvh), prims, config_);
  Result result;
  result.initialFrameCosts.assign(session.frameCosts().begin(), session.frameCosts().end());
  result.initialCost = session.cost();
  const auto record = [&](uint32_t batch) {
    BatchRecord r;
    r.batch = batch;
    r.cost = session.cost();
    r.averageCost = temporalCost(session.frameCosts(), 0);
    r.elapsedSeconds = elapsed();
    r.steps = session.steps();
    r.acceptedSteps = session.acceptedSteps();
    result.history.push_back(r);
    if (config_.progress) config_.progress(r);
  };
  record(0);

  const uint32_t nodeCount = session.bvh().nodeCount();
  const auto batchSize = static_cast<uint32_t>(std::max(
      {1.0, double(config_.minBatchSize), std::round(config_.batchFraction * double(nodeCount))}));
  double best = session.cost();
  uint32_t withoutImprovement = 0;
  bool anyEligible = true;
  for (uint32_t batch = 1; anyEligible; ++batch) {
    if (config_.selection == Selection::BatchSort) {
      const std::vector<uint32_t> nodes = session.batchSortNodes(batchSize);
      anyEligible = !nodes.empty();
      for (std::size_t i = 0; i < nodes.size(); ++i) {
        if (session.eligible(nodes[i])) session.step(nodes[i]);
        if (limited && (i & 31) == 31 && elapsed() >= config_.timeLimitSeconds) break;
      }
    } else {
      for (uint32_t i = 0; i < batchSize; ++i) {
        const uint32_t node = session.selectNode();
        if (node == kInvalidIndex) {
          anyEligible = false;
          break;
        }
        session.step(node);
        if (limited && (i & 31) == 31 && elapsed() >= config_.timeLimitSeconds) break;
      }
    }
    session.refresh();
    record(batch);
    const double cost = session.cost();
    if (cost < best * (1.0 - config_.minImprovement)) {
      best = std::min(best, cost);
      withoutImprovement = 0;
    } else {
      best = std::min(best, cost);
      ++withoutImprovement;
    }
    if (withoutImprovement >= config_.batchesWithoutImprovement) break;
    if (config_.maxBatches && batch >= config_.maxBatches) break;
    if (limited && elapsed() >= config_.timeLimitSeconds) {
      result.timeLimitReached = true;
      break;
    }
  }

  result.finalFrameCosts.assign(session.frameCosts().begin(), session.frameCosts().end());
  result.finalCost = session.cost();
  result.steps = session.steps();
  result.acceptedSteps = session.acceptedSteps();
  result.bvh = session.release();
  result.seconds = elapsed();
  return result;
}

}  // namespace tsah
