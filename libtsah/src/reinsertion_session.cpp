// ReinsertionSession: one round of parallel reinsertion (see parallel_optimizer.hpp).
#include "tsah/parallel_optimizer.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "tsah/cost_terms.hpp"

namespace tsah {

namespace {

// The best position found for one candidate. lca is the lowest common ancestor of L's old and new
// place (the node above which no box changes); lca == target when X is an ancestor of L.
struct Move {
  uint32_t node = kInvalidIndex;    // L
  uint32_t target = kInvalidIndex;  // X
  uint32_t lca = kInvalidIndex;
  float gain = 0.0f;                // A decrease predicted by the search (> 0)
};

// Priority order of conflicting moves: larger gain first, then the smaller node index.
bool higherPriority(const Move& a, const Move& b) {
  return a.gain > b.gain || (a.gain == b.gain && a.node < b.node);
}

struct QueueEntry {
  float induced;
  uint32_t node;
  bool operator<(const QueueEntry& o) const { return induced > o.induced; }  // min-heap
};

// Per-thread scratch of the search, the cost evaluation and the refit.
struct Scratch {
  std::vector<Aabb> moving, without, other, fresh;
  std::vector<QueueEntry> heap;
  std::vector<Move> found;  // improving moves found by this thread in the current round
  uint64_t searched = 0;    // searches by this thread in the current round
  explicit Scratch(uint32_t frames) : moving(frames), without(frames), other(frames), fresh(frames) {}
};

// A uniform number in [0, 1) from (seed, round, node): the candidate sample does not depend on the
// thread count or the order of evaluation.
double sampleOf(uint64_t seed, uint64_t round, uint64_t node) {
  uint64_t z = seed ^ (round * 0x9e3779b97f4a7c15ull) ^ (node * 0xd1b54a32d192ed03ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return double(z >> 11) * 0x1.0p-53;
}

// Frees a vector's storage (`v = {}` assigns an empty initializer list and keeps the capacity).
template <typename T>
void freeStorage(std::vector<T>& v) {
  std::vector<T>().swap(v);
}

inline bool sameBox(const Aabb& a, const Aabb& b) {
  return a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x && a.hi.y == b.hi.y &&
         a.hi.z == b.hi.z;
}

}  // namespace

// Nodes are renumbered: interior nodes [0, innerCount), leaves [innerCount, nodeCount). A leaf's
// left/right hold its primitive range; its boxes are the union of its primitives' boxes.
struct ReinsertionSession::Impl {
  struct Links {
    uint32_t parent, left, right;
  };

  ParallelReinsertionOptimizer::Config config;
  ParallelReinsertionOptimizer::Parallel parallel;
  const PrimitiveBoxes* prims;
  uint32_t frames = 1, nodeCount = 0, innerCount = 0, root = 0;
  uint64_t primTotal = 0;
  std::vector<Links> links;
  std::vector<float> area;       // A(N) with the current weights
  std::vector<Aabb> innerBoxes;  // innerCount * frames, node-major
  std::vector<uint32_t> primIds;
  std::vector<double> rootArea, innerArea, leafArea, frameCost;
  std::vector<float> areaFactor;
  double currentCost = 0.0;
  std::vector<uint8_t> taken;  // per node: touched by a winning move of this round
  // Focus: a node whose last search found nothing is searched again only once a move has touched
  // it or one of its nearest ancestors since (the boxes its search depends on most).
  std::vector<uint32_t> changedIn;   // per node: the last round in which an applied move touched it
  std::vector<uint32_t> quietSince;  // per node: the round its search last found nothing (0: none)
  bool focused = true;               // false: every sampled node is searched (a full round)
  // How far up a focused round looks for changes: the root lies on every path and changes in
  // almost every round, so only the nearest ancestors count.
  static constexpr uint32_t kFocusLevels = 4;
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
    if (config.k < 0) throw std::invalid_argument("ParallelReinsertionOptimizer: the exponent k must be >= 0");
    if (boxes.frameCount == 0) throw std::invalid_argument("ParallelReinsertionOptimizer: no frames");
    if (boxes.primCount != tree.primCount() || boxes.boxes.size() != std::size_t(boxes.frameCount) * boxes.primCount)
      throw std::invalid_argument("ParallelReinsertionOptimizer: the tree holds " + std::to_string(tree.primCount()) +
                                  " primitives, the boxes " + std::to_string(boxes.primCount));
    if (!(parallel.candidateFraction > 0.0) || parallel.candidateFraction > 1.0)
      throw std::invalid_argument("ParallelReinsertionOptimizer: candidateFraction must be in (0, 1]");
    frames = boxes.frameCount;
    tree.boxes.clear();
    tree.boxes.shrink_to_fit();
    adopt(tree);
    primIds = std::move(tree.primIds);
    tree = Bvh{};
    // Allocated only once the input tree is gone: the two are never held together.
    area.assign(nodeCount, 0.0f);
    innerBoxes.assign(std::size_t(innerCount) * frames, Aabb{});
    rootArea.assign(frames, 0.0);
    innerArea.assign(frames, 0.0);
    leafArea.assign(frames, 0.0);
    frameCost.assign(frames, 0.0);
    areaFactor.assign(frames, 0.0f);
    taken.assign(nodeCount, 0);
    changedIn.assign(nodeCount, 0);
    quietSince.assign(nodeCount, 0);
    arena.execute([&] {
      refitAll();
      refresh();
    });
  }

  // The input topology in this numbering (reachable nodes only, as validate() requires).
  void adopt(const Bvh& tree) {
    if (tree.nodes.empty()) throw std::invalid_argument("ParallelReinsertionOptimizer: empty tree");
    std::vector<uint32_t> order = childrenFirstOrder(tree);
    std::vector<uint32_t> id(tree.nodes.size(), kInvalidIndex);
    uint32_t inner = 0, leaves = 0;
    for (uint32_t n : order) (tree.nodes[n].isLeaf() ? leaves : inner)++;
    innerCount = inner;
    nodeCount = inner + leaves;
    uint32_t nextInner = 0, nextLeaf = inner;
    for (uint32_t n : order) id[n] = tree.nodes[n].isLeaf() ? nextLeaf++ : nextInner++;
    links.assign(nodeCount, Links{kInvalidIndex, kInvalidIndex, kInvalidIndex});
    for (uint32_t n : order) {
      const BvhNode& node = tree.nodes[n];
      Links& l = links[id[n]];
      l.parent = node.parent == kInvalidIndex ? kInvalidIndex : id[node.parent];
      if (node.isLeaf()) {
        l.left = node.primBegin;
        l.right = node.primCount;
        primTotal += node.primCount;
      } else {
        l.left = id[node.left];
        l.right = id[node.right];
      }
    }
    root = id[tree.root];
  }

  // ---- boxes ----
  bool isLeaf(uint32_t n) const { return n >= innerCount; }
  Aabb* innerBox(uint32_t n) { return innerBoxes.data() + std::size_t(n) * frames; }
  const Aabb* innerBox(uint32_t n) const { return innerBoxes.data() + std::size_t(n) * frames; }
  void leafBoxes(uint32_t n, Aabb* out) const {
    const Links& l = links[n];
    for (uint32_t f = 0; f < frames; ++f) {
      Aabb b;
      for (uint32_t i = 0; i < l.right; ++i) b.extend(prims->at(f, primIds[l.left + i]));
      out[f] = b;
    }
  }
  // A node's boxes: interior nodes from the array, leaves gathered into `buffer`.
  const Aabb* boxesOf(uint32_t n, std::vector<Aabb>& buffer) const {
    if (!isLeaf(n)) return innerBox(n);
    leafBoxes(n, buffer.data());
    return buffer.data();
  }
  float weighted(const Aabb* b) const { return cost::weightedArea(b, areaFactor.data(), frames); }
  uint32_t sibling(uint32_t n) const {
    const Links& p = links[links[n].parent];
    return p.left == n ? p.right : p.left;
  }
  // Recomputes an interior node's boxes and A(N) from its children.
  void refitNode(uint32_t n, Scratch& s) {
    const Aabb* l = boxesOf(links[n].left, s.other);
    Aabb* b = innerBox(n);
    for (uint32_t f = 0; f < frames; ++f) b[f] = l[f];
    const Aabb* r = boxesOf(links[n].right, s.other);
    for (uint32_t f = 0; f < frames; ++f) b[f].extend(r[f]);
    area[n] = weighted(b);
  }

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
      const uint32_t end = std::min(nodeCount, (c + 1) * kChunk);
      for (uint32_t n = c * kChunk; n < end; ++n) {
        if (links[n].parent == kInvalidIndex && n != root) continue;  // not in the tree
        const Aabb* b = boxesOf(n, s.moving);
        for (uint32_t f = 0; f < frames; ++f) {
          if (isLeaf(n)) leafPart[std::size_t(c) * frames + f] += double(b[f].area()) * links[n].right;
          else innerPart[std::size_t(c) * frames + f] += b[f].area();
        }
      }
    });
    std::fill(innerArea.begin(), innerArea.end(), 0.0);
    std::fill(leafArea.begin(), leafArea.end(), 0.0);
    for (uint32_t c = 0; c < chunks; ++c)
      for (uint32_t f = 0; f < frames; ++f) {
        innerArea[f] += innerPart[std::size_t(c) * frames + f];
        leafArea[f] += leafPart[std::size_t(c) * frames + f];
      }
    Scratch& s = scratch.local();
    const Aabb* rootBoxes = boxesOf(root, s.moving);
    for (uint32_t f = 0; f < frames; ++f) {
      rootArea[f] = rootBoxes[f].area();
      frameCost[f] = cost::frameCost(config.cost.ct, config.cost.ci, innerArea[f], leafArea[f], rootArea[f],
                                     innerCount, primTotal);
    }
    currentCost = cost::temporalCost(frameCost.data(), frames, config.k);
    const std::vector<double> w = temporalWeights(frameCost, config.k);
    for (uint32_t f = 0; f < frames; ++f) areaFactor[f] = cost::areaFactor(w[f], rootArea[f]);
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, nodeCount, 1024), [&](const auto& range) {
      Scratch& local = scratch.local();
      for (uint32_t n = range.begin(); n != range.end(); ++n) area[n] = weighted(boxesOf(n, local.moving));
    });
  }

  bool eligible(uint32_t n) const {
    if (n == root) return false;
    const uint32_t p = links[n].parent;
    return p != kInvalidIndex && p != root;
  }

  // Every eligible node is sampled in a round with probability candidateFraction; in a focused round
  // a sampled node whose last search found nothing is skipped unless its path to the root changed.
  bool isCandidate(uint32_t n) const {
    if (!eligible(n) || sampleOf(config.seed, roundIndex, n) >= parallel.candidateFraction) return false;
    const uint32_t quiet = quietSince[n];
    if (!focused || quiet == 0) return true;
    uint32_t a = n;
    for (uint32_t level = 0; level <= kFocusLevels && a != kInvalidIndex; ++level, a = links[a].parent)
      if (changedIn[a] >= quiet) return true;
    return false;
  }

  // ---- search ----
  // Branch-and-bound over the subtree of u for the X minimizing offset + induced + A(X ∪ L), where
  // induced is the growth of X's ancestors inside the subtree (u included) when L joins X.
  void searchSubtree(uint32_t u, float offset, const Aabb* moving, float movingArea, bool skipRoot, float& best,
                     uint32_t& bestX, Scratch& s) const {
    if (offset + movingArea >= best) return;
    const float direct = offset + cost::weightedUnionArea(boxesOf(u, s.other), moving, areaFactor.data(), frames);
    if (!skipRoot && direct < best) {
      best = direct;
      bestX = u;
    }
    if (isLeaf(u)) return;
    const float induced = direct - area[u];
    if (induced + movingArea >= best) return;
    s.heap.clear();
    s.heap.push_back({induced, u});
    while (!s.heap.empty()) {
      std::pop_heap(s.heap.begin(), s.heap.end());
      const QueueEntry top = s.heap.back();
      s.heap.pop_back();
      if (top.induced + movingArea >= best) break;  // nothing left in the heap can win
      for (const uint32_t x : {links[top.node].left, links[top.node].right}) {
        const float total = top.induced + cost::weightedUnionArea(boxesOf(x, s.other), moving, areaFactor.data(), frames);
        if (total < best) {
          best = total;
          bestX = x;
        }
        if (isLeaf(x)) continue;
        const float next = total - area[x];
        if (next + movingArea >= best) continue;
        s.heap.push_back({next, x});
        std::push_heap(s.heap.begin(), s.heap.end());
      }
    }
  }

  // The best new place for L against the current tree (see the header): walks up from L's parent,
  // `offset` being the cost change so far (P removed, the ancestors below the current one shrunk).
  Move search(uint32_t l, Scratch& s) const {
    const uint32_t p = links[l].parent;
    const float movingArea = area[l];
    for (uint32_t f = 0; f < frames; ++f) s.moving[f] = Aabb{};
    const Aabb* lb = boxesOf(l, s.other);
    std::copy_n(lb, frames, s.moving.data());
    const Aabb* moving = s.moving.data();
    float best = 0.0f;  // leaving L where it is
    uint32_t bestX = kInvalidIndex, bestLca = kInvalidIndex;
    float offset = -area[p];
    const uint32_t siblingOfL = sibling(l);
    searchSubtree(siblingOfL, offset, moving, movingArea, /*skipRoot=*/true, best, bestX, s);
    if (bestX != kInvalidIndex) bestLca = links[p].parent;
    const Aabb* sb = boxesOf(siblingOfL, s.other);
    std::copy_n(sb, frames, s.without.data());
    bool settled = false;  // the path above no longer shrinks without L
    for (uint32_t child = p, node = links[p].parent; node != kInvalidIndex; child = node, node = links[node].parent) {
      if (settled && offset + movingArea >= best) break;  // offsets stay constant from here on
      const uint32_t other = links[node].left == child ? links[node].right : links[node].left;
      const uint32_t before = bestX;
      searchSubtree(other, offset, moving, movingArea, false, best, bestX, s);
      if (bestX != before) bestLca = node;
      const Aabb* ob = boxesOf(other, s.other);
      const Aabb* nb = innerBox(node);
      settled = true;
      for (uint32_t f = 0; f < frames; ++f) {
        s.without[f].extend(ob[f]);
        settled = settled && sameBox(s.without[f], nb[f]);
      }
      const float without = settled ? area[node] : weighted(s.without.data());
      if (offset + without < best) {  // X = this ancestor: it shrinks, the new parent takes its old box
        best = offset + without;
        bestX = node;
        bestLca = node;
      }
      offset += without - area[node];
    }
    if (bestX == kInvalidIndex) return {};
    return {l, bestX, bestLca, -best};
  }

  // ---- the nodes a move touches ----
  // L, P, S, X, X's parent, the old path from L's grandparent up to the lca and the new path from
  // X's parent up to the lca, the lca itself. Every node whose links or boxes the move changes is
  // among them, and so is the parent of every node whose box it changes.
  template <typename F>
  void forEachTouched(const Move& m, F&& visit) const {
    const uint32_t l = m.node, p = links[l].parent, g = links[p].parent;
    visit(l);
    visit(p);
    visit(sibling(l));
    visit(m.target);
    for (uint32_t n = g;; n = links[n].parent) {
      visit(n);
      if (n == m.lca) break;
    }
    if (m.target == m.lca) {  // X is an ancestor: its parent's child link changes
      if (links[m.target].parent != kInvalidIndex) visit(links[m.target].parent);
      return;
    }
    for (uint32_t n = links[m.target].parent; n != m.lca; n = links[n].parent)
      if (n != p) visit(n);
  }

  // The exact per-frame change of the interior area sum if m were applied to the current tree.
  void areaChange(const Move& m, double* delta, Scratch& s) const {
    const uint32_t l = m.node, p = links[l].parent, g = links[p].parent;
    const Aabb* lb = boxesOf(l, s.moving);
    if (lb != s.moving.data()) std::copy_n(lb, frames, s.moving.data());
    const Aabb* pb = innerBox(p);
    for (uint32_t f = 0; f < frames; ++f) delta[f] = -double(pb[f].area());
    // Old path: every node from g up to the lca (the target included when it is an ancestor) loses L.
    const bool ancestor = m.target == m.lca;
    const Aabb* sb = boxesOf(sibling(l), s.other);
    std::copy_n(sb, frames, s.without.data());
    for (uint32_t child = p, n = g; ancestor ? true : n != m.lca; child = n, n = links[n].parent) {
      const uint32_t other = links[n].left == child ? links[n].right : links[n].left;
      const Aabb* ob = boxesOf(other, s.other);
      const Aabb* nb = innerBox(n);
      for (uint32_t f = 0; f < frames; ++f) {
        s.without[f].extend(ob[f]);
        delta[f] += double(s.without[f].area()) - double(nb[f].area());
      }
      if (n == m.target) break;
    }
    // The new parent, and the new path from X's parent up to the lca, which gains L.
    const Aabb* xb = ancestor ? innerBox(m.target) : boxesOf(m.target, s.other);
    for (uint32_t f = 0; f < frames; ++f)
      delta[f] += ancestor ? double(xb[f].area()) : double(merge(xb[f], s.moving[f]).area());
    if (ancestor) return;
    for (uint32_t n = links[m.target].parent; n != m.lca; n = links[n].parent) {
      if (n == p) continue;
      const Aabb* nb = innerBox(n);
      for (uint32_t f = 0; f < frames; ++f) delta[f] += double(merge(nb[f], s.moving[f]).area()) - double(nb[f].area());
    }
  }

  void replaceChild(uint32_t parent, uint32_t oldChild, uint32_t newChild) {
    Links& pl = links[parent];
    if (pl.left == oldChild) pl.left = newChild;
    else pl.right = newChild;
  }

  // Relinks the tree for m (L and P out, S in P's place, P back as the parent of X and L).
  void apply(const Move& m) {
    const uint32_t l = m.node, p = links[l].parent, g = links[p].parent, s = sibling(l);
    replaceChild(g, p, s);
    links[s].parent = g;
    const uint32_t xp = links[m.target].parent;
    links[p] = {xp, m.target, l};
    links[m.target].parent = p;
    links[l].parent = p;
    if (xp == kInvalidIndex) root = p;
    else replaceChild(xp, m.target, p);
  }

  // After apply(): new boxes along both paths, bottom-up.
  void refitPaths(const Move& m, uint32_t oldGrandparent, Scratch& s) {
    const uint32_t p = links[m.node].parent;  // the new parent
    if (m.target == m.lca) {
      for (uint32_t n = oldGrandparent;; n = links[n].parent) {
        refitNode(n, s);
        if (n == m.target) break;
      }
      refitNode(p, s);
      return;
    }
    for (uint32_t n = oldGrandparent; n != m.lca; n = links[n].parent) refitNode(n, s);
    for (uint32_t n = p; n != m.lca; n = links[n].parent) refitNode(n, s);
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
      tbb::parallel_for(tbb::blocked_range<uint32_t>(0, nodeCount, 512), [&](const auto& range) {
        Scratch& s = scratch.local();
        for (uint32_t n = range.begin(); n != range.end(); ++n) {
          if (!isCandidate(n)) continue;
          const Move m = search(n, s);
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
      tbb::parallel_sort(moves.begin(), moves.end(), higherPriority);
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
        areaChange(winners[i], delta.data() + i * frames, scratch.local());
      });
      std::vector<Move> accepted;
      std::vector<uint32_t> grandparents;
      std::vector<double> candidateCost(frames);
      for (std::size_t i = 0; i < winners.size(); ++i) {
        const double* d = delta.data() + i * frames;
        for (uint32_t f = 0; f < frames; ++f)
          candidateCost[f] = cost::frameCost(config.cost.ct, config.cost.ci, innerArea[f] + d[f], leafArea[f],
                                             rootArea[f], innerCount, primTotal);
        const double newCost = cost::temporalCost(candidateCost.data(), frames, config.k);
        if (!(newCost < currentCost)) continue;
        for (uint32_t f = 0; f < frames; ++f) innerArea[f] += d[f];
        frameCost.swap(candidateCost);
        currentCost = newCost;
        accepted.push_back(winners[i]);
        grandparents.push_back(links[links[winners[i].node].parent].parent);
      }
      stats.applied = accepted.size();

      // 5. Apply, then refit the touched paths (disjoint between moves).
      tbb::parallel_for(std::size_t(0), accepted.size(), [&](std::size_t i) {
        forEachTouched(accepted[i], [&](uint32_t n) { changedIn[n] = roundIndex; });
        apply(accepted[i]);
      });
      tbb::parallel_for(std::size_t(0), accepted.size(),
                        [&](std::size_t i) { refitPaths(accepted[i], grandparents[i], scratch.local()); });
    });
    searches += stats.candidates;
    applied += stats.applied;
    return stats;
  }

  void endRound() {
    if (config.k > 0) arena.execute([&] { refresh(); });
  }

  // Node n as a BvhNode (a leaf's links hold its primitive range).
  BvhNode nodeOf(uint32_t n) const {
    BvhNode node;
    node.parent = links[n].parent;
    if (isLeaf(n)) {
      node.primBegin = links[n].left;
      node.primCount = links[n].right;
    } else {
      node.left = links[n].left;
      node.right = links[n].right;
    }
    return node;
  }

  // The tree as the collapser reads it: links, interior boxes, leaf boxes from the primitives.
  CollapseSource collapseSource() const {
    CollapseSource source;
    source.frameCount = frames;
    source.nodeCount = nodeCount;
    source.root = root;
    source.primIds = primIds;
    source.node = [this](uint32_t n) { return nodeOf(n); };
    source.boxes = [this](uint32_t n, Aabb* out) {
      if (isLeaf(n)) leafBoxes(n, out);
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
  Bvh topology() const {
    Bvh out;
    out.frameCount = 0;
    out.root = root;
    out.primIds = primIds;
    out.nodes.resize(nodeCount);
    for (uint32_t n = 0; n < nodeCount; ++n) out.nodes[n] = nodeOf(n);
    return out;
  }
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
std::span<const double> ReinsertionSession::frameCosts() const { return impl_->frameCost; }
Bvh ReinsertionSession::bvh() const {
  Bvh out = impl_->topology();
  refit(out, *impl_->prims);
  return out;
}
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
  const PrimitiveBoxes& prims = *impl_->prims;
  impl_->dropRoundState();
  Bvh out = collapser.collapseTopology(impl_->collapseSource());
  impl_.reset();
  refit(out, prims);
  return out;
}
uint64_t ReinsertionSession::searches() const { return impl_->searches; }
uint64_t ReinsertionSession::appliedMoves() const { return impl_->applied; }

}  // namespace tsah
