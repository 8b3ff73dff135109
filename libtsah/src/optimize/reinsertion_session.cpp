// ReinsertionSession: one round of parallel reinsertion (see parallel_optimizer.hpp).
#include "optimize/optimizer_run.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "tsah/core/cost_terms.hpp"
#include "tsah/optimize/detail/reinsertion_kernels.hpp"
#include "tsah/optimize/detail/reinsertion_rounds.hpp"

namespace tsah {

namespace {

using reinsertion::Move;
using reinsertion::QueueEntry;
namespace rk = reinsertion;

// The search's priority queue on the CPU: the shared heap over storage that grows as needed.
struct GrowingHeap {
  std::vector<QueueEntry> data{64};
  uint32_t size = 0;
  bool empty() const { return size == 0; }
  void clear() { size = 0; }
  void push(QueueEntry e) {
    if (size == data.size()) data.resize(2 * data.size());
    rk::heapPush(data.data(), size, e);
  }
  QueueEntry pop() { return rk::heapPop(data.data(), size); }
};

// Per-thread scratch of the search, the cost evaluation and the refit.
struct Scratch {
  std::vector<Aabb> moving, without, other, fresh;
  GrowingHeap heap;
  std::vector<Move> found;  // improving moves found by this thread in the current round
  uint64_t searched = 0;    // searches by this thread in the current round
  explicit Scratch(uint32_t frames) : moving(frames), without(frames), other(frames), fresh(frames) {}
};

// Frees a vector's storage (`v = {}` assigns an empty initializer list and keeps the capacity).
template <typename T>
void freeStorage(std::vector<T>& v) {
  std::vector<T>().swap(v);
}

}  // namespace

// Nodes are renumbered: interior nodes [0, innerCount), leaves [innerCount, nodeCount). A leaf's
// left/right hold its primitive range; its boxes are the union of its primitives' boxes.
struct ReinsertionSession::Impl {
  using Links = rk::Links;

  ParallelReinsertionOptimizer::Config config;
  ParallelReinsertionOptimizer::Parallel parallel;
  const PrimitiveBoxes* prims;
  uint32_t frames = 1, nodeCount = 0, innerCount = 0, root = 0;
  uint64_t primTotal = 0;
  std::vector<Links> links;
  std::vector<float> area;       // A(N) with the current weights
  std::vector<Aabb> innerBoxes;  // innerCount * frames, node-major
  std::vector<uint32_t> primIds;
  FrameCostTerms terms;
  double currentCost = 0.0;
  std::vector<uint8_t> taken;  // per node: touched by a winning move of this round
  // Focus: a node whose last search found nothing is searched again only once a move has touched
  // it or one of its nearest ancestors since (the boxes its search depends on most).
  std::vector<uint32_t> changedIn;   // per node: the last round in which an applied move touched it
  std::vector<uint32_t> quietSince;  // per node: the round its search last found nothing (0: none)
  bool focused = true;               // false: every sampled node is searched (a full round)
  uint64_t searches = 0, applied = 0;
  uint32_t roundIndex = 0;
  tbb::task_arena arena;
  tbb::enumerable_thread_specific<Scratch> scratch;

  Impl(Bvh tree, const PrimitiveBoxes& boxes, const ParallelReinsertionOptimizer::Config& cfg,
       const ParallelReinsertionOptimizer::Parallel& par)
      : config(cfg),
        parallel(par),
        prims(&boxes),
        arena(par.threads ? int(par.threads) : tbb::task_arena::automatic),
        scratch([f = std::max(1u, boxes.frameCount)] { return Scratch(f); }) {
    rk::checkReinsertionInput(tree, boxes, config, parallel);
    frames = boxes.frameCount;
    tree.boxes.clear();
    tree.boxes.shrink_to_fit();
    adopt(tree);
    primIds = std::move(tree.primIds);
    tree = Bvh{};
    // Allocated only once the input tree is gone: the two are never held together.
    area.assign(nodeCount, 0.0f);
    innerBoxes.assign(std::size_t(innerCount) * frames, Aabb{});
    terms.reset(frames);
    taken.assign(nodeCount, 0);
    changedIn.assign(nodeCount, 0);
    quietSince.assign(nodeCount, 0);
    arena.execute([&] {
      refitAll();
      refresh();
    });
  }

  // The input topology in the optimizer's numbering (reachable nodes only, as validate() requires).
  void adopt(const Bvh& tree) {
    rk::NumberedTree numbered = rk::numberTree(tree);
    links = std::move(numbered.links);
    innerCount = numbered.innerCount;
    nodeCount = numbered.nodeCount;
    root = numbered.root;
    primTotal = numbered.primTotal;
  }

  // ---- boxes (reinsertion_kernels.hpp does the arithmetic) ----
  // The session's arrays as the shared per-thread functions see them (allocated once, so the
  // pointers stay valid).
  rk::TreeView view() const {
    auto* self = const_cast<Impl*>(this);
    return {self->links.data(), self->innerBoxes.data(), self->area.data(), prims->boxes.data(), primIds.data(),
            terms.areaFactor.data(),  &self->root,             frames,            innerCount,          nodeCount,
            prims->primCount,   true};
  }
  static rk::Buffers buffers(Scratch& s) { return {s.moving.data(), s.without.data(), s.other.data()}; }
  bool isLeaf(uint32_t n) const { return n >= innerCount; }
  const Aabb* innerBox(uint32_t n) const { return innerBoxes.data() + std::size_t(n) * frames; }
  void refitNode(uint32_t n, Scratch& s) { rk::refitNode(view(), n, s.other.data()); }

  void refitAll() {
    // Interior nodes by depth, deepest first: each level depends only on the one below it.
    std::vector<uint32_t> depth(innerCount, 0);
    std::vector<uint32_t> stack{root};
    uint32_t deepest = 0;
    std::vector<std::vector<uint32_t>> levels;
    while (!stack.empty()) {
      const uint32_t n = stack.back();
      stack.pop_back();
      if (isLeaf(n)) continue;
      const uint32_t d = links[n].parent == kInvalidIndex ? 0 : depth[links[n].parent] + 1;
      depth[n] = d;
      deepest = std::max(deepest, d);
      if (levels.size() <= d) levels.resize(d + 1);
      levels[d].push_back(n);
      stack.push_back(links[n].left);
      stack.push_back(links[n].right);
    }
    for (std::size_t d = levels.size(); d-- > 0;)
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, levels[d].size(), 256), [&](const auto& range) {
        Scratch& s = scratch.local();
        for (std::size_t i = range.begin(); i != range.end(); ++i) refitNode(levels[d][i], s);
      });
  }

  // Frame costs from the boxes (fixed chunks, so the sums do not depend on the thread count), the
  // weights w_i = C_i^k and every node's A(N).
  void refresh() {
    constexpr uint32_t kChunk = 1u << 14;
    const uint32_t chunks = (nodeCount + kChunk - 1) / kChunk;
    std::vector<double> innerPart(std::size_t(chunks) * frames, 0.0), leafPart(std::size_t(chunks) * frames, 0.0);
    tbb::parallel_for(uint32_t(0), chunks, [&](uint32_t c) {
      Scratch& s = scratch.local();
      rk::addAreaSums(view(), c * kChunk, std::min(nodeCount, (c + 1) * kChunk), &innerPart[std::size_t(c) * frames],
                      &leafPart[std::size_t(c) * frames], s.moving.data());
    });
    std::fill(terms.innerArea.begin(), terms.innerArea.end(), 0.0);
    std::fill(terms.leafArea.begin(), terms.leafArea.end(), 0.0);
    for (uint32_t c = 0; c < chunks; ++c)
      for (uint32_t f = 0; f < frames; ++f) {
        terms.innerArea[f] += innerPart[std::size_t(c) * frames + f];
        terms.leafArea[f] += leafPart[std::size_t(c) * frames + f];
      }
    Scratch& s = scratch.local();
    const Aabb* rootBoxes = rk::boxesOf(view(), root, s.moving.data());
    for (uint32_t f = 0; f < frames; ++f) terms.rootArea[f] = rootBoxes[f].area();
    currentCost = terms.updateFrameCosts(config.cost, innerCount, primTotal, config.k);
    terms.updateAreaFactors(config.k);
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, nodeCount, 1024), [&](const auto& range) {
      Scratch& local = scratch.local();
      const rk::TreeView t = view();
      for (uint32_t n = range.begin(); n != range.end(); ++n)
        area[n] = rk::weighted(t, rk::boxesOf(t, n, local.moving.data()));
    });
  }

  template <typename F>
  void forEachTouched(const Move& m, F&& visit) const {
    rk::forEachTouched(view(), m, visit);
  }

  RoundStats round(bool focusedRound) {
    focused = focusedRound;
    RoundStats stats;
    ++roundIndex;
    arena.execute([&] {
      // 1-2. Candidates and their searches.
      for (Scratch& s : scratch) {
        s.found.clear();
        s.searched = 0;
      }
      const rk::TreeView t = view();
      const rk::CandidateRule rule{config.seed, roundIndex, parallel.candidateFraction, focused, changedIn.data(),
                                   quietSince.data()};
      tbb::parallel_for(tbb::blocked_range<uint32_t>(0, nodeCount, 512), [&](const auto& range) {
        Scratch& s = scratch.local();
        for (uint32_t n = range.begin(); n != range.end(); ++n) {
          if (!rk::isCandidate(t, rule, n)) continue;
          const Move m = rk::search(t, n, buffers(s), s.heap);
          ++s.searched;
          quietSince[n] = m.node == kInvalidIndex ? roundIndex : 0;
          if (m.node != kInvalidIndex) s.found.push_back(m);
        }
      });
      for (Scratch& s : scratch) stats.candidates += s.searched;
      std::vector<Move> moves;
      std::size_t found = 0;
      for (Scratch& s : scratch) found += s.found.size();
      moves.reserve(found);
      for (Scratch& s : scratch) {  // the per-thread lists are freed: early rounds find millions of moves
        moves.insert(moves.end(), s.found.begin(), s.found.end());
        freeStorage(s.found);
      }
      tbb::parallel_sort(moves.begin(), moves.end(), rk::higherPriority);
      stats.improving = moves.size();

      // 3. Conflicts: in priority order, a move wins when none of its nodes was taken by a winner
      // before it (a maximal set of moves with disjoint nodes, independent of the thread count).
      std::vector<Move> winners;
      for (const Move& m : moves) {
        bool free = true;
        forEachTouched(m, [&](uint32_t n) { free = free && !taken[n]; });
        if (!free) continue;
        forEachTouched(m, [&](uint32_t n) { taken[n] = 1; });
        winners.push_back(m);
      }
      for (const Move& m : winners) forEachTouched(m, [&](uint32_t n) { taken[n] = 0; });
      freeStorage(moves);
      stats.winners = winners.size();

      // 4. Exact cost changes (parallel), kept in priority order while they lower C~^k.
      std::vector<double> delta(winners.size() * frames);
      tbb::parallel_for(std::size_t(0), winners.size(), [&](std::size_t i) {
        rk::areaChange(t, winners[i], delta.data() + i * frames, buffers(scratch.local()));
      });
      std::vector<Move> accepted;
      std::vector<double> candidateCost(frames);
      const rk::FrameSums sums = frameSums();
      for (std::size_t i = 0; i < winners.size(); ++i) {
        const double* d = delta.data() + i * frames;
        const double newCost = rk::costWithChange(sums, d, candidateCost.data());
        if (!(newCost < currentCost)) continue;
        for (uint32_t f = 0; f < frames; ++f) terms.innerArea[f] += d[f];
        terms.frameCost.swap(candidateCost);
        currentCost = newCost;
        accepted.push_back(winners[i]);
      }
      stats.applied = accepted.size();

      // 5. Apply, then refit the touched paths (disjoint between moves).
      std::vector<uint32_t> grandparents(accepted.size());
      tbb::parallel_for(std::size_t(0), accepted.size(), [&](std::size_t i) {
        forEachTouched(accepted[i], [&](uint32_t n) { changedIn[n] = roundIndex; });
        grandparents[i] = rk::apply(t, accepted[i]);
      });
      tbb::parallel_for(std::size_t(0), accepted.size(), [&](std::size_t i) {
        rk::refitPaths(t, accepted[i], grandparents[i], scratch.local().other.data());
      });
    });
    searches += stats.candidates;
    applied += stats.applied;
    return stats;
  }

  rk::FrameSums frameSums() const {
    return {terms.innerArea.data(), terms.leafArea.data(), terms.rootArea.data(), frames, innerCount, primTotal,
            config.cost.ct,   config.cost.ci,  config.k};
  }

  void endRound() {
    if (config.k > 0) arena.execute([&] { refresh(); });
  }

  // Node n as a BvhNode (a leaf's links hold its primitive range).
  BvhNode nodeOf(uint32_t n) const { return rk::nodeOf(links[n], isLeaf(n)); }


  // The tree as the collapser reads it: links, interior boxes, leaf boxes from the primitives.
  CollapseSource collapseSource() const {
    CollapseSource source;
    source.frameCount = frames;
    source.nodeCount = nodeCount;
    source.root = root;
    source.primIds = primIds;
    source.node = [this](uint32_t n) { return nodeOf(n); };
    source.boxes = [this](uint32_t n, Aabb* out) {
      if (isLeaf(n)) rk::leafBoxes(view(), n, out);
      else std::copy_n(innerBox(n), frames, out);
    };
    return source;
  }

  // Frees what only rounds use (A(N), flags, round stamps), before the collapse allocates.
  void dropRoundState() {
    freeStorage(area);
    freeStorage(taken);
    freeStorage(changedIn);
    freeStorage(quietSince);
  }

  // The topology as a Bvh without boxes (frameCount 0).
  Bvh topology() const { return rk::topologyOf(links, primIds, root, innerCount); }
};

ReinsertionSession::ReinsertionSession(Bvh bvh, const PrimitiveBoxes& prims,
                                       const ParallelReinsertionOptimizer::Config& config,
                                       const ParallelReinsertionOptimizer::Parallel& parallel)
    : impl_(std::make_unique<Impl>(std::move(bvh), prims, config, parallel)) {}
ReinsertionSession::~ReinsertionSession() = default;
ReinsertionSession::ReinsertionSession(ReinsertionSession&&) noexcept = default;
ReinsertionSession& ReinsertionSession::operator=(ReinsertionSession&&) noexcept = default;

ReinsertionSession::RoundStats ReinsertionSession::round(bool focused) { return impl_->round(focused); }
void ReinsertionSession::endRound() { impl_->endRound(); }
double ReinsertionSession::cost() const { return impl_->currentCost; }
std::span<const double> ReinsertionSession::frameCosts() const { return impl_->terms.frameCost; }
std::vector<double> ReinsertionSession::frameCostList() const { return impl_->terms.frameCost; }
Bvh ReinsertionSession::releaseTree(const LeafCollapser* collapse) {
  return collapse ? releaseCollapsed(*collapse) : release();
}
Bvh ReinsertionSession::bvh() const {
  Bvh out = impl_->topology();
  refit(out, *impl_->prims);
  return out;
}
Bvh ReinsertionSession::topology() const { return impl_->topology(); }
// The session's boxes are freed before the tree's are computed: the two are never held together.
Bvh ReinsertionSession::release() {
  const PrimitiveBoxes& prims = *impl_->prims;
  Bvh out = impl_->topology();
  impl_.reset();
  refit(out, prims);
  return out;
}
// The collapse reads the session's own boxes, then the session is freed and the (smaller) collapsed
// tree's boxes are computed from the primitives: every node's boxes of every frame are never copied.
Bvh ReinsertionSession::releaseCollapsed(const LeafCollapser& collapser) {
  impl_->dropRoundState();
  return releaseCollapsedTree(impl_, collapser);
}
uint64_t ReinsertionSession::searches() const { return impl_->searches; }
uint64_t ReinsertionSession::appliedMoves() const { return impl_->applied; }

}  // namespace tsah
