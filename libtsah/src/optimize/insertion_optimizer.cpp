#include "tsah/optimize/insertion_optimizer.hpp"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "optimize/random.hpp"
#include "optimize/optimizer_run.hpp"
#include "tsah/base/assert.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost_terms.hpp"

namespace tsah {

namespace {

inline bool sameBox(const Aabb& a, const Aabb& b) {
  return a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x &&
         a.hi.y == b.hi.y && a.hi.z == b.hi.z;
}

struct QueueEntry {
  float induced;
  uint32_t node;
};

}  // namespace

// Node records are packed for the search: one 24-byte header followed by the node's boxes of all
// frames, so a visited node costs one or two neighbouring cache lines. The header is stored in an
// Aabb slot (6 x 4 bytes) through std::bit_cast, which keeps the storage a plain array of boxes.
//   lo.x left child   lo.y right child   lo.z A(N)   hi.x Delta_N   hi.y parent   hi.z leaf flag
struct InsertionSession::Impl {
  InsertionOptimizer::Config config;
  const PrimitiveBoxes* prims;  // the leaves' boxes, for releaseCollapsed
  uint32_t frames = 1;
  uint32_t nodeCount = 0;
  std::size_t stride = 2;          // slots per node record: header + frames boxes
  std::vector<Aabb> records;
  uint32_t root = 0;
  std::vector<uint32_t> interior;  // interior nodes: a fixed set (N and P are reused as parents)
  // Node selection proposes interior nodes by the thousand: their Delta_N lives in this compact
  // mirror of the headers (by position in `interior`), so a proposal touches one small array.
  struct Proposal {
    uint32_t node;
    float delta;
  };
  std::vector<Proposal> proposals;
  std::vector<uint32_t> proposalIndex;  // node -> position in `proposals` (interior nodes only)
  Bvh shape;                       // leaves' primitive ranges, primIds; the topology when materialized
  mutable bool shapeCurrent = true;

  // Per frame.
  FrameCostTerms terms;  // S_i and the leaf sums stay constant here; the interior sums and C_i change
  std::vector<float> deltaFactor;  // w_i / W: Delta_N = sum_i deltaFactor_i * S_N(i)
  uint64_t innerCount = 0, primTotal = 0;
  double currentCost = 0.0;

  // Step state: undo log of every node record touched, per-frame change of the interior area sum.
  std::vector<uint32_t> undoNodes;
  std::vector<Aabb> undoRecords;
  std::vector<uint32_t> touchedInStep;
  uint32_t stepStamp = 0;
  uint32_t savedRoot = 0;
  std::vector<double> stepAreaChange;
  std::vector<double> candidateCost;
  std::vector<Aabb> scratchBoxes;
  std::vector<QueueEntry> heap;

  Rng rng;
  uint32_t chainNode = kInvalidIndex;  // last node accepted by the Metropolis-Hastings chain
  uint64_t steps = 0, accepted = 0;

  Impl(Bvh tree, const PrimitiveBoxes& primitives, const InsertionOptimizer::Config& cfg)
      : config(cfg), prims(&primitives), shape(std::move(tree)), rng(cfg.seed) {
    if (config.k < 0) throw tsah::ConfigError("InsertionOptimizer: the exponent k must be >= 0");
    if (primitives.frameCount == 0) throw tsah::DataError("InsertionOptimizer: no frames");
    if (primitives.primCount != shape.primCount())
      throw tsah::DataError("InsertionOptimizer: the tree holds " + std::to_string(shape.primCount()) +
                            " primitives, the boxes " + std::to_string(primitives.primCount));
    // The input's boxes are not needed: the records are refitted from the primitives directly
    // (the same boxes refit() gives), so every node's boxes are never held twice.
    shape.boxes.clear();
    shape.boxes.shrink_to_fit();
    frames = primitives.frameCount;
    shape.frameCount = frames;
    nodeCount = shape.nodeCount();
    stride = std::size_t(frames) + 1;
    root = shape.root;
    records.resize(std::size_t(nodeCount) * stride);
    for (uint32_t n = 0; n < nodeCount; ++n) {
      const BvhNode& node = shape.nodes[n];
      setLeft(n, node.left);
      setRight(n, node.right);
      setParent(n, node.parent);
      header(n).hi.z = std::bit_cast<float>(uint32_t(node.isLeaf()));
      if (node.isLeaf()) primTotal += node.primCount;
      else interior.push_back(n);
    }
    refitInto(shape, primitives, [this](uint32_t n) { return box(n); });
    innerCount = interior.size();
    proposalIndex.assign(nodeCount, kInvalidIndex);
    for (std::size_t i = 0; i < interior.size(); ++i) {
      proposals.push_back({interior[i], 0.0f});
      proposalIndex[interior[i]] = static_cast<uint32_t>(i);
    }
    shapeCurrent = false;

    terms.reset(frames);
    deltaFactor.assign(frames, 0.0f);
    stepAreaChange.assign(frames, 0.0);
    candidateCost.assign(frames, 0.0);
    scratchBoxes.resize(frames);
    touchedInStep.assign(nodeCount, 0);
    heap.reserve(256);
    refresh(/*weights=*/true);
  }

  // ---- node records ----
  Aabb& header(uint32_t n) { return records[std::size_t(n) * stride]; }
  const Aabb& header(uint32_t n) const { return records[std::size_t(n) * stride]; }
  Aabb* box(uint32_t n) { return records.data() + std::size_t(n) * stride + 1; }
  const Aabb* box(uint32_t n) const { return records.data() + std::size_t(n) * stride + 1; }
  uint32_t left(uint32_t n) const { return std::bit_cast<uint32_t>(header(n).lo.x); }
  uint32_t right(uint32_t n) const { return std::bit_cast<uint32_t>(header(n).lo.y); }
  float area(uint32_t n) const { return header(n).lo.z; }
  float delta(uint32_t n) const { return header(n).hi.x; }
  void setDelta(uint32_t n, float d) {
    header(n).hi.x = d;
    if (proposalIndex[n] != kInvalidIndex) proposals[proposalIndex[n]].delta = d;
  }
  uint32_t parent(uint32_t n) const { return std::bit_cast<uint32_t>(header(n).hi.y); }
  bool isLeaf(uint32_t n) const { return std::bit_cast<uint32_t>(header(n).hi.z) != 0; }
  void setLeft(uint32_t n, uint32_t v) { header(n).lo.x = std::bit_cast<float>(v); }
  void setRight(uint32_t n, uint32_t v) { header(n).lo.y = std::bit_cast<float>(v); }
  void setParent(uint32_t n, uint32_t v) { header(n).hi.y = std::bit_cast<float>(v); }
  void prefetch(uint32_t n) const {
    const char* p = reinterpret_cast<const char*>(&header(n));
    for (std::size_t offset = 0; offset < stride * sizeof(Aabb); offset += 64) __builtin_prefetch(p + offset);
  }

  // The tree as the collapser reads it, straight from the records.
  CollapseSource collapseSource() const {
    CollapseSource source;
    source.frameCount = frames;
    source.nodeCount = nodeCount;
    source.root = root;
    source.primIds = shape.primIds;
    source.node = [this](uint32_t n) {
      BvhNode node = shape.nodes[n];  // leaves: the primitive range
      node.parent = parent(n);
      if (!isLeaf(n)) {
        node.left = left(n);
        node.right = right(n);
      }
      return node;
    };
    source.boxes = [this](uint32_t n, Aabb* out) { std::copy_n(box(n), frames, out); };
    return source;
  }

  // The tree as a Bvh (topology from the records, primitive ranges and ids from the input).
  const Bvh& materialize() const {
    if (shapeCurrent) return shape;
    Bvh& out = const_cast<Bvh&>(shape);
    out.root = root;
    out.frameCount = frames;
    out.boxes.resize(std::size_t(nodeCount) * frames);
    for (uint32_t n = 0; n < nodeCount; ++n) {
      BvhNode& node = out.nodes[n];
      node.parent = parent(n);
      if (!isLeaf(n)) {
        node.left = left(n);
        node.right = right(n);
      }
      std::copy_n(box(n), frames, &out.box(n, 0));
    }
    shapeCurrent = true;
    return shape;
  }

  double costOf(std::span<const double> costs) const { return temporalCost(costs, config.k); }

  // A(N) and Delta_N = sum_i (w_i / W) S_N(i): the same weighted area with other factors.
  void updateNodeCaches(uint32_t n) {
    header(n).lo.z = cost::weightedArea(box(n), terms.areaFactor.data(), frames);
    setDelta(n, cost::weightedArea(box(n), deltaFactor.data(), frames));
  }

  // Recomputes the frame costs from the boxes; with `weights`, also w_i and every node's A and Delta.
  void refresh(bool weights) {
    std::fill(terms.innerArea.begin(), terms.innerArea.end(), 0.0);
    std::fill(terms.leafArea.begin(), terms.leafArea.end(), 0.0);
    for (uint32_t n = 0; n < nodeCount; ++n) {
      const Aabb* b = box(n);
      if (isLeaf(n)) {
        const double count = shape.nodes[n].primCount;
        for (uint32_t f = 0; f < frames; ++f) terms.leafArea[f] += double(b[f].area()) * count;
      } else {
        for (uint32_t f = 0; f < frames; ++f) terms.innerArea[f] += b[f].area();
      }
    }
    for (uint32_t f = 0; f < frames; ++f) terms.rootArea[f] = box(root)[f].area();
    currentCost = terms.updateFrameCosts(config.cost, innerCount, primTotal, config.k);
    if (!weights) return;
    const std::vector<double> w = terms.updateAreaFactors(config.k);
    for (uint32_t f = 0; f < frames; ++f) deltaFactor[f] = float(w[f]);
    for (uint32_t n = 0; n < nodeCount; ++n) updateNodeCaches(n);
  }

  // After a batch: the frame costs are tracked exactly step by step, so only k > 0 needs work (new
  // weights, hence new cached areas).
  void endBatch() {
    if (config.k > 0) refresh(true);
    else currentCost = costOf(terms.frameCost);
  }

  bool eligible(uint32_t n) const {
    if (n >= nodeCount || isLeaf(n) || n == root) return false;
    return parent(n) != root;
  }

  // ---- undo log ----
  void save(uint32_t n) {
    if (touchedInStep[n] == stepStamp) return;
    touchedInStep[n] = stepStamp;
    undoNodes.push_back(n);
    const Aabb* r = &header(n);
    undoRecords.insert(undoRecords.end(), r, r + stride);
  }

  void undo() {
    for (std::size_t e = 0; e < undoNodes.size(); ++e) {
      const uint32_t n = undoNodes[e];
      std::copy_n(undoRecords.data() + e * stride, stride, &header(n));
      setDelta(n, delta(n));
    }
    root = savedRoot;
  }

  void replaceChild(uint32_t p, uint32_t oldChild, uint32_t newChild) {
    if (left(p) == oldChild) setLeft(p, newChild);
    else setRight(p, newChild);
  }

  // Recomputes boxes from the children upwards, stopping at the first node whose boxes did not
  // change (its ancestors cannot change either); records the area change of every frame.
  void refitUpward(uint32_t n) {
    Aabb* fresh = scratchBoxes.data();
    while (n != kInvalidIndex) {
      const Aabb* l = box(left(n));
      const Aabb* r = box(right(n));
      Aabb* b = box(n);
      bool changed = false;
      for (uint32_t f = 0; f < frames; ++f) {
        fresh[f] = merge(l[f], r[f]);
        changed |= !sameBox(fresh[f], b[f]);
      }
      if (!changed) return;
      save(n);
      for (uint32_t f = 0; f < frames; ++f) {
        stepAreaChange[f] += double(fresh[f].area()) - double(b[f].area());
        b[f] = fresh[f];
      }
      updateNodeCaches(n);
      n = parent(n);
    }
  }

  // Weighted multi-frame area of the union of node x's boxes and the given boxes (from `records`).
  float unionCost(uint32_t x, const Aabb* c) const {
    return cost::weightedUnionArea(box(x), c, terms.areaFactor.data(), frames);
  }

  void push(QueueEntry e) {
    heap.push_back(e);
    std::size_t i = heap.size() - 1;
    while (i > 0) {
      const std::size_t up = (i - 1) / 2;
      if (heap[up].induced <= e.induced) break;
      heap[i] = heap[up];
      i = up;
    }
    heap[i] = e;
  }

  QueueEntry pop() {
    const QueueEntry top = heap.front();
    const QueueEntry last = heap.back();
    heap.pop_back();
    const std::size_t size = heap.size();
    if (size == 0) return top;
    std::size_t i = 0;
    for (;;) {
      std::size_t child = 2 * i + 1;
      if (child >= size) break;
      if (child + 1 < size && heap[child + 1].induced < heap[child].induced) ++child;
      if (last.induced <= heap[child].induced) break;
      heap[i] = heap[child];
      i = child;
    }
    heap[i] = last;
    return top;
  }

  // Branch-and-bound: the node X for which making c a sibling of X raises the cost least. A queue
  // entry (induced, X) means X's children are still to be examined, each with that induced cost
  // (the growth of X and its ancestors); both children are evaluated together when X comes out.
  uint32_t findBestSibling(uint32_t c) {
    const Aabb* cb = box(c);
    const float areaC = area(c);
    uint32_t bestNode = root;
    float best = unionCost(root, cb);
    heap.clear();
    if (!isLeaf(root)) {
      const float induced = best - area(root);
      if (induced + areaC < best) push({induced, root});
    }
    while (!heap.empty()) {
      const QueueEntry top = pop();
      // A child's direct cost is at least A(c): nothing left in the queue can beat `best`.
      if (top.induced + areaC >= best) break;
      const uint32_t children[2] = {left(top.node), right(top.node)};
      for (const uint32_t x : children) {
        const float total = top.induced + unionCost(x, cb);
        if (total < best) {
          best = total;
          bestNode = x;
        }
        if (isLeaf(x)) continue;
        const float induced = total - area(x);  // x grows by (union - A(x)) when c goes below it
        if (induced + areaC >= best) continue;
        push({induced, x});
        prefetch(left(x));
        prefetch(right(x));
      }
    }
    return bestNode;
  }

  // Makes the detached subtree c a child of the free node q, with the best sibling X in the tree.
  void insert(uint32_t c, uint32_t q) {
    const uint32_t x = findBestSibling(c);
    const uint32_t xp = parent(x);
    save(x);
    save(q);
    save(c);
    if (xp != kInvalidIndex) save(xp);
    setParent(q, xp);
    setLeft(q, x);
    setRight(q, c);
    setParent(x, q);
    setParent(c, q);
    if (xp == kInvalidIndex) root = q;
    else replaceChild(xp, x, q);
    Aabb* b = box(q);
    const Aabb* xb = box(x);
    const Aabb* cb = box(c);
    for (uint32_t f = 0; f < frames; ++f) {
      b[f] = merge(xb[f], cb[f]);
      stepAreaChange[f] += b[f].area();
    }
    updateNodeCaches(q);
    refitUpward(xp);
  }

  bool step(uint32_t n) {
    if (!eligible(n)) throw tsah::ConfigError("InsertionSession::step: node is not eligible");
    ++steps;
    ++stepStamp;
    if (stepStamp == 0) {  // wrapped: clear the stamps so no node looks touched
      std::fill(touchedInStep.begin(), touchedInStep.end(), 0);
      stepStamp = 1;
    }
    shapeCurrent = false;
    undoNodes.clear();
    undoRecords.clear();
    savedRoot = root;
    std::fill(stepAreaChange.begin(), stepAreaChange.end(), 0.0);

    const uint32_t p = parent(n);
    const uint32_t g = parent(p);
    const uint32_t s = left(p) == n ? right(p) : left(p);
    uint32_t first = left(n), second = right(n);
    for (uint32_t touched : {n, p, g, s, first, second}) save(touched);

    // Detach N and P: the sibling takes P's place, the interior areas of N and P leave the cost.
    for (uint32_t f = 0; f < frames; ++f)
      stepAreaChange[f] -= double(box(n)[f].area()) + double(box(p)[f].area());
    replaceChild(g, p, s);
    setParent(s, g);
    refitUpward(g);

    // Reinsert N's children, the larger first, reusing N and P as their new parents.
    if (area(second) > area(first)) std::swap(first, second);
    insert(first, n);
    insert(second, p);

    for (uint32_t f = 0; f < frames; ++f)
      candidateCost[f] = terms.rootArea[f] > 0.0
                             ? terms.frameCost[f] + config.cost.ct * stepAreaChange[f] / terms.rootArea[f]
                             : terms.frameCost[f];
    const double newCost = costOf(candidateCost);
    if (newCost > currentCost) {
      undo();
      return false;
    }
    terms.frameCost.swap(candidateCost);
    for (uint32_t f = 0; f < frames; ++f) terms.innerArea[f] += stepAreaChange[f];
    currentCost = newCost;
    ++accepted;
    return true;
  }

  // Uniform over eligible nodes: interior nodes by rejection of the root and its children.
  // Returns the position in `proposals`, or kInvalidIndex when no node is eligible.
  uint32_t uniformProposal() {
    const auto count = static_cast<uint32_t>(proposals.size());
    if (count < 4) {  // too few interior nodes for the rejection loop to be sure to end
      for (uint32_t i = 0; i < count; ++i)
        if (eligible(proposals[i].node)) return i;
      return kInvalidIndex;
    }
    const uint32_t rootLeft = left(root), rootRight = right(root);
    for (;;) {
      const uint32_t i = rng.below(count);
      const uint32_t n = proposals[i].node;
      if (n != root && n != rootLeft && n != rootRight) return i;
    }
  }

  uint32_t uniformEligible() {
    const uint32_t i = uniformProposal();
    return i == kInvalidIndex ? kInvalidIndex : proposals[i].node;
  }

  uint32_t selectMetropolisHastings() {
    if (chainNode == kInvalidIndex) {
      chainNode = uniformEligible();
      return chainNode;
    }
    // Independent chain: propose uniformly, accept with min(1, Delta_new / Delta_current); go on
    // until a node other than the last accepted one is accepted (re-optimizing the same node
    // would find the same position again).
    const float current = delta(chainNode);
    const uint64_t limit = 64 * uint64_t(nodeCount) + 4096;  // only tiny trees get near it
    uint32_t proposal = kInvalidIndex;
    for (uint64_t i = 0; i < limit; ++i) {
      const uint32_t p = uniformProposal();
      if (p == kInvalidIndex) return kInvalidIndex;
      proposal = proposals[p].node;
      const float d = proposals[p].delta;
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
    for (uint32_t n : interior) {
      if (!eligible(n)) continue;
      const double a = area(n);
      const double l = area(left(n)), r = area(right(n));
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
void InsertionSession::refresh() { impl_->refresh(true); }
void InsertionSession::endBatch() { impl_->endBatch(); }
double InsertionSession::cost() const { return impl_->currentCost; }
std::span<const double> InsertionSession::frameCosts() const { return impl_->terms.frameCost; }
const Bvh& InsertionSession::bvh() const { return impl_->materialize(); }
Bvh InsertionSession::release() {
  impl_->materialize();
  return std::move(impl_->shape);
}
// The collapse reads the node records; they are freed before the collapsed tree's boxes are
// computed from the primitives, so every node's boxes are never held twice.
Bvh InsertionSession::releaseCollapsed(const LeafCollapser& collapser) { return releaseCollapsedTree(impl_, collapser); }
uint32_t InsertionSession::nodeCount() const { return impl_->nodeCount; }
uint64_t InsertionSession::steps() const { return impl_->steps; }
uint64_t InsertionSession::acceptedSteps() const { return impl_->accepted; }

void throwIfCancelled(const InsertionOptimizer::Config& config) {
  if (config.cancelled && config.cancelled()) throw Cancelled("optimization cancelled");
}

InsertionOptimizer::InsertionOptimizer(Config config) : config_(std::move(config)) {
  if (config_.k < 0) throw tsah::ConfigError("InsertionOptimizer: the exponent k must be >= 0");
  if (!(config_.batchFraction > 0.0) || config_.batchFraction > 1.0)
    throw tsah::ConfigError("InsertionOptimizer: batchFraction must be in (0, 1]");
  if (config_.batchesWithoutImprovement == 0)
    throw tsah::ConfigError("InsertionOptimizer: batchesWithoutImprovement must be >= 1");
}

InsertionOptimizer::Result InsertionOptimizer::optimize(Bvh bvh, const PrimitiveBoxes& prims,
                                                       const LeafCollapser* collapse) const {
  const auto start = OptimizerRun::Clock::now();
  InsertionSession session(std::move(bvh), prims, config_);
  const auto state = [&session] {
    return RunState{session.cost(), session.frameCosts(), session.steps(), session.acceptedSteps()};
  };
  OptimizerRun run(config_, start, state());

  const uint32_t nodeCount = session.nodeCount();  // not bvh(): that would copy every node's boxes
  const auto batchSize = static_cast<uint32_t>(std::max(
      {1.0, double(config_.minBatchSize), std::round(config_.batchFraction * double(nodeCount))}));
  // Within a batch the cancel check and the time limit are looked at every 32 steps.
  const auto outOfTime = [&run](std::size_t i) {
    if ((i & 31) != 31) return false;
    run.throwIfCancelled();
    return run.pastTimeLimit();
  };
  bool anyEligible = true;
  for (uint32_t batch = 1; anyEligible; ++batch) {
    if (config_.selection == Selection::BatchSort) {
      const std::vector<uint32_t> nodes = session.batchSortNodes(batchSize);
      anyEligible = !nodes.empty();
      for (std::size_t i = 0; i < nodes.size(); ++i) {
        if (session.eligible(nodes[i])) session.step(nodes[i]);
        if (outOfTime(i)) break;
      }
    } else {
      for (uint32_t i = 0; i < batchSize; ++i) {
        const uint32_t node = session.selectNode();
        if (node == kInvalidIndex) {
          anyEligible = false;
          break;
        }
        session.step(node);
        if (outOfTime(i)) break;
      }
    }
    session.endBatch();
    // Debug builds: the tree is still a tree over every primitive, each box holding its children's
    // and primitives' boxes in every frame (bvh() materializes the boxes; release builds skip both).
    TSAH_ASSERT_VALID(validate(session.bvh(), &prims),
                      "insertion optimizer: the tree after batch " + std::to_string(batch));
    if (run.endBatch(batch, state()) || run.limitReached(batch)) break;
  }
  run.finalState(state());
  return run.finish(collapse ? session.releaseCollapsed(*collapse) : session.release());
}

}  // namespace tsah
