#pragma once
// The per-thread arithmetic of parallel reinsertion (parallel_optimizer.hpp) on plain pointers, one
// copy for every backend: the CPU session (reinsertion_session.cpp, TBB), the GPU rounds
// (cuda_kernels/src/reinsertion.cu) and their serial host emulation (reinsertion_rounds.hpp). Every
// function here is what one thread does for one node or one move: the branch-and-bound search of a
// candidate, the set of nodes a move touches, a move's exact area change, applying a move, refitting
// its paths, a chunk of the frame area sums.
//
// Nodes are numbered interior [0, innerCount), leaves [innerCount, nodeCount). A leaf's left/right
// hold its primitive range; its boxes are the union of its primitives' boxes (read, not stored).
#include <cstdint>
#include <cstring>

#include "tsah/core/aabb.hpp"
#include "tsah/core/cost_terms.hpp"
#include "tsah/core/hd.hpp"

namespace tsah::reinsertion {

inline constexpr uint32_t kNone = 0xffffffffu;  // tsah::kInvalidIndex

struct Links {
  uint32_t parent, left, right;
};

// The best position found for one candidate. lca is the lowest common ancestor of L's old and new
// place (the node above which no box changes); lca == target when X is an ancestor of L.
struct Move {
  uint32_t node = kNone;    // L
  uint32_t target = kNone;  // X
  uint32_t lca = kNone;
  float gain = 0.0f;        // A decrease predicted by the search (> 0)
};

// Priority order of conflicting moves: larger gain first, then the smaller node index.
TSAH_HD bool higherPriority(const Move& a, const Move& b) {
  return a.gain > b.gain || (a.gain == b.gain && a.node < b.node);
}

// The same order as one 64-bit number (larger: higher priority), for atomicMax and radix sorts. A
// positive float's bits order like the float.
TSAH_HD uint64_t priorityKey(const Move& m) {
  uint32_t bits;
  std::memcpy(&bits, &m.gain, sizeof bits);
  return (uint64_t(bits) << 32) | uint64_t(0xffffffffu - m.node);
}

// The tree under optimization as plain pointers (host or device memory alike).
struct TreeView {
  Links* links;
  Aabb* innerBoxes;        // innerCount * frames, node-major
  float* area;             // A(N) per node with the current weights
  const Aabb* primBoxes;   // frames * primCount, frame-major (PrimitiveBoxes::boxes)
  const uint32_t* primIds;
  const float* areaFactor; // per frame
  uint32_t* root;
  uint32_t frames, innerCount, nodeCount, primCount;
  bool simd;  // host only: SSE union areas (false: the portable arithmetic the GPU uses)
};

// ---- a binary min-heap on induced cost, over caller storage ----
struct QueueEntry {
  float induced;
  uint32_t node;
};

TSAH_HD void heapPush(QueueEntry* heap, uint32_t& size, QueueEntry entry) {
  uint32_t i = size++;
  while (i > 0) {
    const uint32_t parent = (i - 1) / 2;
    if (!(entry.induced < heap[parent].induced)) break;
    heap[i] = heap[parent];
    i = parent;
  }
  heap[i] = entry;
}

TSAH_HD QueueEntry heapPop(QueueEntry* heap, uint32_t& size) {
  const QueueEntry top = heap[0];
  const QueueEntry last = heap[--size];
  uint32_t i = 0;
  for (;;) {
    uint32_t child = 2 * i + 1;
    if (child >= size) break;
    if (child + 1 < size && heap[child + 1].induced < heap[child].induced) ++child;
    if (!(heap[child].induced < last.induced)) break;
    heap[i] = heap[child];
    i = child;
  }
  if (size > 0) heap[i] = last;
  return top;
}

// A heap of fixed capacity in thread-local storage (GPU threads and their emulation). A full heap
// drops new entries: the search then skips that subtree (still a valid, deterministic move).
template <uint32_t Capacity>
struct FixedHeap {
  QueueEntry data[Capacity];
  uint32_t size = 0;
  TSAH_HD bool empty() const { return size == 0; }
  TSAH_HD void clear() { size = 0; }
  TSAH_HD void push(QueueEntry e) {
    if (size < Capacity) heapPush(data, size, e);
  }
  TSAH_HD QueueEntry pop() { return heapPop(data, size); }
};

// ---- boxes and areas ----
TSAH_HD bool isLeaf(const TreeView& t, uint32_t n) { return n >= t.innerCount; }
TSAH_HD Aabb* innerBox(const TreeView& t, uint32_t n) { return t.innerBoxes + std::size_t(n) * t.frames; }

TSAH_HD void leafBoxes(const TreeView& t, uint32_t n, Aabb* out) {
  const Links l = t.links[n];
  for (uint32_t f = 0; f < t.frames; ++f) {
    Aabb b;
    const Aabb* frame = t.primBoxes + std::size_t(f) * t.primCount;
    for (uint32_t i = 0; i < l.right; ++i) b.extend(frame[t.primIds[l.left + i]]);
    out[f] = b;
  }
}

// A node's boxes: interior nodes from the array, leaves gathered into `buffer` (frames boxes).
TSAH_HD const Aabb* boxesOf(const TreeView& t, uint32_t n, Aabb* buffer) {
  if (!isLeaf(t, n)) return innerBox(t, n);
  leafBoxes(t, n, buffer);
  return buffer;
}

TSAH_HD float weighted(const TreeView& t, const Aabb* b) { return cost::weightedArea(b, t.areaFactor, t.frames); }

TSAH_HD float weightedUnion(const TreeView& t, const Aabb* a, const Aabb* b) {
  return t.simd ? cost::weightedUnionArea(a, b, t.areaFactor, t.frames)
                : cost::weightedUnionAreaPortable(a, b, t.areaFactor, t.frames);
}

TSAH_HD bool sameBox(const Aabb& a, const Aabb& b) {
  return a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x && a.hi.y == b.hi.y &&
         a.hi.z == b.hi.z;
}

TSAH_HD uint32_t sibling(const TreeView& t, uint32_t n) {
  const Links p = t.links[t.links[n].parent];
  return p.left == n ? p.right : p.left;
}

// Recomputes an interior node's boxes and A(N) from its children.
TSAH_HD void refitNode(const TreeView& t, uint32_t n, Aabb* buffer) {
  const Aabb* l = boxesOf(t, t.links[n].left, buffer);
  Aabb* b = innerBox(t, n);
  for (uint32_t f = 0; f < t.frames; ++f) b[f] = l[f];
  const Aabb* r = boxesOf(t, t.links[n].right, buffer);
  for (uint32_t f = 0; f < t.frames; ++f) b[f].extend(r[f]);
  t.area[n] = weighted(t, b);
}

// Adds the interior areas and the primitive-weighted leaf areas of nodes [begin, end) (those in the
// tree) to inner[f] and leaf[f]: one chunk of the frame cost sums (Eq. 1).
TSAH_HD void addAreaSums(const TreeView& t, uint32_t begin, uint32_t end, double* inner, double* leaf, Aabb* buffer) {
  const uint32_t root = *t.root;
  for (uint32_t n = begin; n < end; ++n) {
    if (t.links[n].parent == kNone && n != root) continue;  // not in the tree
    const Aabb* b = boxesOf(t, n, buffer);
    for (uint32_t f = 0; f < t.frames; ++f) {
      if (isLeaf(t, n)) leaf[f] += double(b[f].area()) * t.links[n].right;
      else inner[f] += b[f].area();
    }
  }
}

// ---- candidates ----
// How far up a focused round looks for changes: the root lies on every path and changes in almost
// every round, so only the nearest ancestors count.
inline constexpr uint32_t kFocusLevels = 4;

// Not the root, not a child of the root.
TSAH_HD bool eligible(const TreeView& t, uint32_t n) {
  const uint32_t p = t.links[n].parent;
  return p != kNone && t.links[p].parent != kNone;
}

// A uniform number in [0, 1) from (seed, round, node): the candidate sample does not depend on the
// thread count or the order of evaluation.
TSAH_HD double sampleOf(uint64_t seed, uint64_t round, uint64_t node) {
  uint64_t z = seed ^ (round * 0x9e3779b97f4a7c15ull) ^ (node * 0xd1b54a32d192ed03ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return double(z >> 11) * 0x1.0p-53;
}

// The candidate rule of one round: sampled with probability `fraction`; in a focused round a node
// whose last search found nothing (quietSince > 0) only once a move touched it or one of its
// nearest ancestors since.
struct CandidateRule {
  uint64_t seed;
  uint32_t round;
  double fraction;
  bool focused;
  const uint32_t* changedIn;   // per node: the last round in which an applied move touched it
  const uint32_t* quietSince;  // per node: the round its search last found nothing (0: none)
};

TSAH_HD bool isCandidate(const TreeView& t, const CandidateRule& r, uint32_t n) {
  if (!eligible(t, n) || sampleOf(r.seed, r.round, n) >= r.fraction) return false;
  const uint32_t quiet = r.quietSince[n];
  if (!r.focused || quiet == 0) return true;
  uint32_t a = n;
  for (uint32_t level = 0; level <= kFocusLevels && a != kNone; ++level, a = t.links[a].parent)
    if (r.changedIn[a] >= quiet) return true;
  return false;
}

// ---- search ----
// Per-thread box buffers of `frames` boxes each.
struct Buffers {
  Aabb* moving;
  Aabb* without;
  Aabb* other;
};

// Branch-and-bound over the subtree of u for the X minimizing offset + induced + A(X ∪ L), where
// induced is the growth of X's ancestors inside the subtree (u included) when L joins X.
template <class Heap>
TSAH_HD void searchSubtree(const TreeView& t, uint32_t u, float offset, const Aabb* moving, float movingArea,
                           bool skipRoot, float& best, uint32_t& bestX, Heap& heap, Aabb* other) {
  if (offset + movingArea >= best) return;
  const float direct = offset + weightedUnion(t, boxesOf(t, u, other), moving);
  if (!skipRoot && direct < best) {
    best = direct;
    bestX = u;
  }
  if (isLeaf(t, u)) return;
  const float induced = direct - t.area[u];
  if (induced + movingArea >= best) return;
  heap.clear();
  heap.push({induced, u});
  while (!heap.empty()) {
    const QueueEntry top = heap.pop();
    if (top.induced + movingArea >= best) break;  // nothing left in the heap can win
    const Links node = t.links[top.node];
    for (int side = 0; side < 2; ++side) {
      const uint32_t x = side == 0 ? node.left : node.right;
      const float total = top.induced + weightedUnion(t, boxesOf(t, x, other), moving);
      if (total < best) {
        best = total;
        bestX = x;
      }
      if (isLeaf(t, x)) continue;
      const float next = total - t.area[x];
      if (next + movingArea >= best) continue;
      heap.push({next, x});
    }
  }
}

// The best new place for L against the current tree (see parallel_optimizer.hpp): walks up from
// L's parent, `offset` being the cost change so far (P removed, the ancestors below shrunk).
// Returns a Move with node == kNone when no position lowers A.
template <class Heap>
TSAH_HD Move search(const TreeView& t, uint32_t l, const Buffers& s, Heap& heap) {
  const uint32_t p = t.links[l].parent;
  const float movingArea = t.area[l];
  const Aabb* lb = boxesOf(t, l, s.other);
  for (uint32_t f = 0; f < t.frames; ++f) s.moving[f] = lb[f];
  const Aabb* moving = s.moving;
  float best = 0.0f;  // leaving L where it is
  uint32_t bestX = kNone, bestLca = kNone;
  float offset = -t.area[p];
  const uint32_t siblingOfL = sibling(t, l);
  searchSubtree(t, siblingOfL, offset, moving, movingArea, /*skipRoot=*/true, best, bestX, heap, s.other);
  if (bestX != kNone) bestLca = t.links[p].parent;
  const Aabb* sb = boxesOf(t, siblingOfL, s.other);
  for (uint32_t f = 0; f < t.frames; ++f) s.without[f] = sb[f];
  bool settled = false;  // the path above no longer shrinks without L
  for (uint32_t child = p, node = t.links[p].parent; node != kNone; child = node, node = t.links[node].parent) {
    if (settled && offset + movingArea >= best) break;  // offsets stay constant from here on
    const Links nl = t.links[node];
    const uint32_t otherChild = nl.left == child ? nl.right : nl.left;
    const uint32_t before = bestX;
    searchSubtree(t, otherChild, offset, moving, movingArea, false, best, bestX, heap, s.other);
    if (bestX != before) bestLca = node;
    const Aabb* ob = boxesOf(t, otherChild, s.other);
    const Aabb* nb = innerBox(t, node);
    settled = true;
    for (uint32_t f = 0; f < t.frames; ++f) {
      s.without[f].extend(ob[f]);
      settled = settled && sameBox(s.without[f], nb[f]);
    }
    const float without = settled ? t.area[node] : weighted(t, s.without);
    if (offset + without < best) {  // X = this ancestor: it shrinks, the new parent takes its old box
      best = offset + without;
      bestX = node;
      bestLca = node;
    }
    offset += without - t.area[node];
  }
  Move m;
  if (bestX == kNone) return m;
  m.node = l;
  m.target = bestX;
  m.lca = bestLca;
  m.gain = -best;
  return m;
}

// ---- the nodes a move touches ----
// L, P, S, X, X's parent, the old path from L's grandparent up to the lca and the new path from X's
// parent up to the lca, the lca itself. Every node whose links or boxes the move changes is among
// them, and so is the parent of every node whose box it changes: moves with disjoint sets can be
// applied and refitted side by side, and their cost changes add up exactly.
template <typename Visit>
TSAH_HD void forEachTouched(const TreeView& t, const Move& m, Visit&& visit) {
  const uint32_t l = m.node, p = t.links[l].parent, g = t.links[p].parent;
  visit(l);
  visit(p);
  visit(sibling(t, l));
  visit(m.target);
  for (uint32_t n = g;; n = t.links[n].parent) {
    visit(n);
    if (n == m.lca) break;
  }
  if (m.target == m.lca) {  // X is an ancestor: its parent's child link changes
    if (t.links[m.target].parent != kNone) visit(t.links[m.target].parent);
    return;
  }
  for (uint32_t n = t.links[m.target].parent; n != m.lca; n = t.links[n].parent)
    if (n != p) visit(n);
}

// The exact per-frame change of the interior area sum if m were applied to the current tree.
TSAH_HD void areaChange(const TreeView& t, const Move& m, double* delta, const Buffers& s) {
  const uint32_t l = m.node, p = t.links[l].parent, g = t.links[p].parent;
  const Aabb* lb = boxesOf(t, l, s.moving);
  if (lb != s.moving)
    for (uint32_t f = 0; f < t.frames; ++f) s.moving[f] = lb[f];
  const Aabb* pb = innerBox(t, p);
  for (uint32_t f = 0; f < t.frames; ++f) delta[f] = -double(pb[f].area());
  // Old path: every node from g up to the lca (the target included when it is an ancestor) loses L.
  const bool ancestor = m.target == m.lca;
  const Aabb* sb = boxesOf(t, sibling(t, l), s.other);
  for (uint32_t f = 0; f < t.frames; ++f) s.without[f] = sb[f];
  for (uint32_t child = p, n = g; ancestor ? true : n != m.lca; child = n, n = t.links[n].parent) {
    const uint32_t other = t.links[n].left == child ? t.links[n].right : t.links[n].left;
    const Aabb* ob = boxesOf(t, other, s.other);
    const Aabb* nb = innerBox(t, n);
    for (uint32_t f = 0; f < t.frames; ++f) {
      s.without[f].extend(ob[f]);
      delta[f] += double(s.without[f].area()) - double(nb[f].area());
    }
    if (n == m.target) break;
  }
  // The new parent, and the new path from X's parent up to the lca, which gains L.
  const Aabb* xb = ancestor ? innerBox(t, m.target) : boxesOf(t, m.target, s.other);
  for (uint32_t f = 0; f < t.frames; ++f)
    delta[f] += ancestor ? double(xb[f].area()) : double(merge(xb[f], s.moving[f]).area());
  if (ancestor) return;
  for (uint32_t n = t.links[m.target].parent; n != m.lca; n = t.links[n].parent) {
    if (n == p) continue;
    const Aabb* nb = innerBox(t, n);
    for (uint32_t f = 0; f < t.frames; ++f)
      delta[f] += double(merge(nb[f], s.moving[f]).area()) - double(nb[f].area());
  }
}

// ---- applying a move ----
TSAH_HD void replaceChild(const TreeView& t, uint32_t parent, uint32_t oldChild, uint32_t newChild) {
  Links& pl = t.links[parent];
  if (pl.left == oldChild) pl.left = newChild;
  else pl.right = newChild;
}

// Relinks the tree for m (L and P out, S in P's place, P back as the parent of X and L). Returns
// L's old grandparent, where refitPaths starts. Writes only nodes of m's touched set.
TSAH_HD uint32_t apply(const TreeView& t, const Move& m) {
  const uint32_t l = m.node, p = t.links[l].parent, g = t.links[p].parent, s = sibling(t, l);
  replaceChild(t, g, p, s);
  t.links[s].parent = g;
  const uint32_t xp = t.links[m.target].parent;
  t.links[p] = {xp, m.target, l};
  t.links[m.target].parent = p;
  t.links[l].parent = p;
  if (xp == kNone) *t.root = p;
  else replaceChild(t, xp, m.target, p);
  return g;
}

// After apply(): new boxes along both paths, bottom-up (only nodes of m's touched set).
TSAH_HD void refitPaths(const TreeView& t, const Move& m, uint32_t oldGrandparent, Aabb* buffer) {
  const uint32_t p = t.links[m.node].parent;  // the new parent
  if (m.target == m.lca) {
    for (uint32_t n = oldGrandparent;; n = t.links[n].parent) {
      refitNode(t, n, buffer);
      if (n == m.target) break;
    }
    refitNode(t, p, buffer);
    return;
  }
  for (uint32_t n = oldGrandparent; n != m.lca; n = t.links[n].parent) refitNode(t, n, buffer);
  for (uint32_t n = p; n != m.lca; n = t.links[n].parent) refitNode(t, n, buffer);
}

// ---- costs of a round ----
// The frame sums that Eq. 1 needs, as the optimizer tracks them.
struct FrameSums {
  const double* innerArea;
  const double* leafArea;
  const double* rootArea;
  uint32_t frames;
  uint64_t innerCount, primCount;
  float ct, ci;
  int k;
};

// C~^k with the interior area sums changed by delta (per frame); the frame costs go to frameCost.
TSAH_HD double costWithChange(const FrameSums& s, const double* delta, double* frameCost) {
  for (uint32_t f = 0; f < s.frames; ++f)
    frameCost[f] = cost::frameCost(s.ct, s.ci, s.innerArea[f] + (delta ? delta[f] : 0.0), s.leafArea[f],
                                   s.rootArea[f], s.innerCount, s.primCount);
  return cost::temporalCost(frameCost, s.frames, s.k);
}

// d C~^k / d innerArea_f at the current frame costs: the first-order change of the cost by a move
// is sum_f gradient_f * delta_f (exact for k = 0, where C~^0 is linear in the area sums).
TSAH_HD void costGradient(const FrameSums& s, const double* frameCost, double* gradient) {
  double largest = 0.0;
  for (uint32_t f = 0; f < s.frames; ++f) largest = frameCost[f] > largest ? frameCost[f] : largest;
  double sumK = 0.0, sumK1 = 0.0;  // sum x^k, sum x^(k+1) with x = C / largest
  for (uint32_t f = 0; f < s.frames; ++f) {
    const double x = largest > 0.0 ? frameCost[f] / largest : 1.0;
    const double xk = cost::integerPower(x, s.k);
    sumK += xk;
    sumK1 += xk * x;
  }
  for (uint32_t f = 0; f < s.frames; ++f) {
    const double x = largest > 0.0 ? frameCost[f] / largest : 1.0;
    const double dCost = s.k == 0 ? 1.0 / double(s.frames)
                                  : (double(s.k + 1) * cost::integerPower(x, s.k) * sumK -
                                     double(s.k) * cost::integerPower(x, s.k - 1) * sumK1) /
                                        (sumK * sumK);
    gradient[f] = s.rootArea[f] > 0.0 ? dCost * double(s.ct) / s.rootArea[f] : 0.0;
  }
}

}  // namespace tsah::reinsertion
