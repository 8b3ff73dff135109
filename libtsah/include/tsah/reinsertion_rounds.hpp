#pragma once
// The GPU form of parallel reinsertion: one round as a fixed sequence of phases, each phase one
// data-parallel loop ("kernel") whose body is a function object below, calling only the shared
// per-thread arithmetic of reinsertion_kernels.hpp. ReinsertionRounds<Backend> runs the sequence;
// the CUDA backend (cuda_kernels/src/reinsertion.cu) launches every phase as a kernel, the host
// backend (reinsertion_emulation.cpp) as a serial loop over the thread indices. A phase never
// depends on the order of its threads (the one atomic is a max of unique keys), so both give the
// same tree, bit for bit, for a seed.
//
// A round (see parallel_optimizer.hpp for the move and its cost):
//   1. mark candidates (the CPU optimizer's seeded, focused rule), compact them in node order;
//   2. search: one thread per candidate, a bounded local heap;
//   3. compact the improving moves; claim passes: every undecided move atomicMax-es its priority
//      key (gain, then node index) into the nodes it touches, a move that owns all of them wins and
//      takes them, undecided moves that touch a taken node lose. Run to the end, the passes give
//      exactly the CPU optimizer's greedy winners; kClaimPasses bounds them (the rest wait a round);
//   4. the winners' exact area changes, sorted by priority;
//   5. acceptance: a winner is kept when its first-order change of C~^k is negative (exact for
//      k = 0); the kept changes are summed in a fixed order and checked exactly on the device; if
//      the sum would not lower C~^k (possible only for k > 0), a single thread redoes the
//      acceptance as the CPU optimizer does (in priority order, each kept only when it lowers C~^k);
//   6. apply the kept moves, then refit their paths (disjoint node sets: no two threads write one
//      node).
// Between rounds (k > 0): frame sums in fixed chunks, new weights, every node's A(N).
#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "tsah/bvh.hpp"
#include "tsah/leaf_collapser.hpp"
#include "tsah/parallel_optimizer.hpp"
#include "tsah/reinsertion_kernels.hpp"

namespace tsah::reinsertion {

// Representative frames a device thread can hold in its local buffers.
inline constexpr uint32_t kMaxDeviceFrames = 16;
// Entries of a device thread's search heap (a full heap skips subtrees, see FixedHeap).
inline constexpr uint32_t kDeviceHeapCapacity = 64;
// Claim passes per round.
inline constexpr uint32_t kClaimPasses = 4;
// Nodes per thread of the frame area sums; winners per thread of the accepted-change sums; rows
// per thread when partial sums are reduced further (until one thread can add up the rest).
inline constexpr uint32_t kAreaChunk = 1024;
inline constexpr uint32_t kDeltaChunk = 256;
inline constexpr uint32_t kRowsPerThread = 64;

// Move status during the claim passes.
enum : uint8_t { kUndecided = 0, kWon = 1, kLost = 2 };

TSAH_HD void claimMax(unsigned long long* slot, unsigned long long key) {
#if defined(__CUDA_ARCH__)
  atomicMax(slot, key);
#else
  if (key > *slot) *slot = key;
#endif
}

// The round's scalars on the device, as offsets into one array of doubles.
struct Scalars {
  uint32_t frames;
  TSAH_HD uint32_t innerArea() const { return 0; }
  TSAH_HD uint32_t leafArea() const { return frames; }
  TSAH_HD uint32_t rootArea() const { return 2 * frames; }
  TSAH_HD uint32_t frameCost() const { return 3 * frames; }
  TSAH_HD uint32_t gradient() const { return 4 * frames; }
  TSAH_HD uint32_t cost() const { return 5 * frames; }
  TSAH_HD uint32_t fallback() const { return 5 * frames + 1; }  // 1.0: the linear acceptance failed
  TSAH_HD uint32_t size() const { return 5 * frames + 2; }
};

// What a phase needs of the cost model.
struct CostSettings {
  float ct, ci;
  int k;
  uint64_t innerCount, primCount;
};

TSAH_HD FrameSums frameSums(const double* scalars, const Scalars& at, const CostSettings& c) {
  return {scalars + at.innerArea(), scalars + at.leafArea(), scalars + at.rootArea(), at.frames,
          c.innerCount,             c.primCount,             c.ct,                    c.ci,
          c.k};
}

// ---- phases: one object per kernel, operator()(i) is thread i's work ----
struct MarkCandidates {
  TreeView t;
  CandidateRule rule;
  uint8_t* flags;
  TSAH_HD void operator()(uint32_t n) const { flags[n] = isCandidate(t, rule, n) ? 1 : 0; }
};

// The search with the frame count as a compile-time constant: its loops unroll and the moving
// boxes can stay in registers. The same arithmetic in the same order as the general search.
template <uint32_t Frames, class Heap>
TSAH_HD Move searchWithFrames(TreeView t, uint32_t l, const Buffers& s, Heap& heap) {
  t.frames = Frames;
  return search(t, l, s, heap);
}

template <class Heap>
TSAH_HD Move searchSpecialized(const TreeView& t, uint32_t l, const Buffers& s, Heap& heap) {
  switch (t.frames) {
    case 1: return searchWithFrames<1>(t, l, s, heap);
    case 2: return searchWithFrames<2>(t, l, s, heap);
    case 3: return searchWithFrames<3>(t, l, s, heap);
    case 4: return searchWithFrames<4>(t, l, s, heap);
    case 5: return searchWithFrames<5>(t, l, s, heap);
    case 8: return searchWithFrames<8>(t, l, s, heap);
    default: return search(t, l, s, heap);
  }
}

// Specialized: the search compiled for common frame counts (more registers per thread, fewer
// threads in flight); which is faster is the device's question (profileOnGpu times both).
template <bool Specialized>
struct SearchCandidates {
  TreeView t;
  const uint32_t* candidates;
  Move* moves;       // per candidate
  uint8_t* found;    // per candidate: 1 when its search found a move
  uint32_t* quietSince;
  uint32_t round;
  TSAH_HD void operator()(uint32_t i) const {
    Aabb moving[kMaxDeviceFrames], without[kMaxDeviceFrames], other[kMaxDeviceFrames];
    FixedHeap<kDeviceHeapCapacity> heap;
    const uint32_t n = candidates[i];
    const Buffers buffers{moving, without, other};
    const Move m = Specialized ? searchSpecialized(t, n, buffers, heap) : search(t, n, buffers, heap);
    moves[i] = m;
    found[i] = m.node != kNone ? 1 : 0;
    quietSince[n] = m.node == kNone ? round : 0;
  }
};

struct ClaimNodes {
  TreeView t;
  const Move* moves;
  const uint32_t* improving;  // improving move -> candidate slot
  const uint8_t* status;
  unsigned long long* owner;  // per node
  TSAH_HD void operator()(uint32_t i) const {
    if (status[i] != kUndecided) return;
    const Move m = moves[improving[i]];
    const unsigned long long key = priorityKey(m);
    forEachTouched(t, m, [&](uint32_t n) { claimMax(owner + n, key); });
  }
};

struct DecideWinners {
  TreeView t;
  const Move* moves;
  const uint32_t* improving;
  uint8_t* status;
  const unsigned long long* owner;
  uint8_t* taken;  // per node
  TSAH_HD void operator()(uint32_t i) const {
    if (status[i] != kUndecided) return;
    const Move m = moves[improving[i]];
    const unsigned long long key = priorityKey(m);
    bool ownsAll = true;
    forEachTouched(t, m, [&](uint32_t n) { ownsAll = ownsAll && owner[n] == key; });
    if (!ownsAll) return;
    status[i] = kWon;
    forEachTouched(t, m, [&](uint32_t n) { taken[n] = 1; });
  }
};

struct EliminateLosers {
  TreeView t;
  const Move* moves;
  const uint32_t* improving;
  uint8_t* status;
  const uint8_t* taken;
  TSAH_HD void operator()(uint32_t i) const {
    if (status[i] != kUndecided) return;
    bool free = true;
    forEachTouched(t, moves[improving[i]], [&](uint32_t n) { free = free && !taken[n]; });
    if (!free) status[i] = kLost;
  }
};

struct FlagWinners {
  const uint8_t* status;
  uint8_t* flags;
  TSAH_HD void operator()(uint32_t i) const { flags[i] = status[i] == kWon ? 1 : 0; }
};

// Winner w (an index into the improving list) -> its priority key and its candidate slot.
struct WinnerKeys {
  const Move* moves;
  const uint32_t* improving;
  const uint32_t* winners;
  unsigned long long* keys;
  uint32_t* slots;
  TSAH_HD void operator()(uint32_t w) const {
    const uint32_t slot = improving[winners[w]];
    keys[w] = priorityKey(moves[slot]);
    slots[w] = slot;
  }
};

struct AreaChanges {
  TreeView t;
  const Move* moves;
  const uint32_t* slots;  // winners in priority order
  double* delta;          // winners * frames
  TSAH_HD void operator()(uint32_t w) const {
    Aabb moving[kMaxDeviceFrames], without[kMaxDeviceFrames], other[kMaxDeviceFrames];
    areaChange(t, moves[slots[w]], delta + std::size_t(w) * t.frames, Buffers{moving, without, other});
  }
};

// One thread: d C~^k / d innerArea_f from the current frame costs.
struct Gradient {
  double* scalars;
  Scalars at;
  CostSettings cost;
  TSAH_HD void operator()(uint32_t) const {
    costGradient(frameSums(scalars, at, cost), scalars + at.frameCost(), scalars + at.gradient());
  }
};

struct LinearAcceptance {
  const double* delta;
  const double* scalars;
  Scalars at;
  uint8_t* accept;
  TSAH_HD void operator()(uint32_t w) const {
    double change = 0.0;
    for (uint32_t f = 0; f < at.frames; ++f) change += scalars[at.gradient() + f] * delta[std::size_t(w) * at.frames + f];
    accept[w] = change < 0.0 ? 1 : 0;
  }
};

// Thread g: rows [g * kRowsPerThread, ...) of a rows x columns matrix of partial sums, added in
// order into row g of `out` (one level of a fixed-order reduction).
struct SumRows {
  const double* in;
  uint32_t rows, columns;
  double* out;
  TSAH_HD void operator()(uint32_t g) const {
    double* o = out + std::size_t(g) * columns;
    for (uint32_t c = 0; c < columns; ++c) o[c] = 0.0;
    const uint32_t end = (g + 1) * kRowsPerThread < rows ? (g + 1) * kRowsPerThread : rows;
    for (uint32_t r = g * kRowsPerThread; r < end; ++r)
      for (uint32_t c = 0; c < columns; ++c) o[c] += in[std::size_t(r) * columns + c];
  }
};

// Thread c: the accepted changes of winners [c * kDeltaChunk, ...) summed in order.
struct SumAccepted {
  const double* delta;
  const uint8_t* accept;
  uint32_t winners, frames;
  double* partial;  // chunks * frames
  TSAH_HD void operator()(uint32_t c) const {
    double* out = partial + std::size_t(c) * frames;
    for (uint32_t f = 0; f < frames; ++f) out[f] = 0.0;
    const uint32_t end = (c + 1) * kDeltaChunk < winners ? (c + 1) * kDeltaChunk : winners;
    for (uint32_t w = c * kDeltaChunk; w < end; ++w)
      if (accept[w])
        for (uint32_t f = 0; f < frames; ++f) out[f] += delta[std::size_t(w) * frames + f];
  }
};

// One thread: the summed change checked exactly; committed when it lowers C~^k, else the fallback
// flag is raised.
struct CommitAccepted {
  const double* partial;
  uint32_t chunks;
  double* scalars;
  Scalars at;
  CostSettings cost;
  TSAH_HD void operator()(uint32_t) const {
    double total[kMaxDeviceFrames], frameCost[kMaxDeviceFrames];
    for (uint32_t f = 0; f < at.frames; ++f) total[f] = 0.0;
    for (uint32_t c = 0; c < chunks; ++c)
      for (uint32_t f = 0; f < at.frames; ++f) total[f] += partial[std::size_t(c) * at.frames + f];
    const double newCost = costWithChange(frameSums(scalars, at, cost), total, frameCost);
    if (chunks > 0 && !(newCost < scalars[at.cost()])) {
      scalars[at.fallback()] = 1.0;
      return;
    }
    scalars[at.fallback()] = 0.0;
    if (chunks == 0) return;
    for (uint32_t f = 0; f < at.frames; ++f) {
      scalars[at.innerArea() + f] += total[f];
      scalars[at.frameCost() + f] = frameCost[f];
    }
    scalars[at.cost()] = newCost;
  }
};

// One thread, only after a failed check: the CPU optimizer's acceptance, in priority order.
struct SerialAcceptance {
  const double* delta;
  uint32_t winners;
  uint8_t* accept;
  double* scalars;
  Scalars at;
  CostSettings cost;
  TSAH_HD void operator()(uint32_t) const {
    double frameCost[kMaxDeviceFrames];
    for (uint32_t w = 0; w < winners; ++w) {
      const double* d = delta + std::size_t(w) * at.frames;
      const double newCost = costWithChange(frameSums(scalars, at, cost), d, frameCost);
      accept[w] = newCost < scalars[at.cost()] ? 1 : 0;
      if (!accept[w]) continue;
      for (uint32_t f = 0; f < at.frames; ++f) {
        scalars[at.innerArea() + f] += d[f];
        scalars[at.frameCost() + f] = frameCost[f];
      }
      scalars[at.cost()] = newCost;
    }
  }
};

struct ApplyMoves {
  TreeView t;
  const Move* moves;
  const uint32_t* slots;
  const uint32_t* accepted;  // indices into slots
  uint32_t* changedIn;
  uint32_t round;
  uint32_t* grandparents;    // per accepted move
  TSAH_HD void operator()(uint32_t a) const {
    const Move m = moves[slots[accepted[a]]];
    forEachTouched(t, m, [&](uint32_t n) { changedIn[n] = round; });
    grandparents[a] = apply(t, m);
  }
};

struct RefitMoves {
  TreeView t;
  const Move* moves;
  const uint32_t* slots;
  const uint32_t* accepted;
  const uint32_t* grandparents;
  TSAH_HD void operator()(uint32_t a) const {
    Aabb buffer[kMaxDeviceFrames];
    refitPaths(t, moves[slots[accepted[a]]], grandparents[a], buffer);
  }
};

// Thread c: the frame area sums of nodes [c * kAreaChunk, ...), as row c: frames interior sums,
// then frames leaf sums.
struct AreaSums {
  TreeView t;
  double* sums;  // chunks * 2 * frames
  TSAH_HD void operator()(uint32_t c) const {
    Aabb buffer[kMaxDeviceFrames];
    double* in = sums + std::size_t(c) * 2 * t.frames;
    double* le = in + t.frames;
    for (uint32_t f = 0; f < t.frames; ++f) in[f] = le[f] = 0.0;
    const uint32_t end = (c + 1) * kAreaChunk < t.nodeCount ? (c + 1) * kAreaChunk : t.nodeCount;
    addAreaSums(t, c * kAreaChunk, end, in, le, buffer);
  }
};

// One thread: frame costs, C~^k, the weights w_i = C_i^k and the area factors (the CPU session's
// refresh()).
struct RefreshCosts {
  TreeView t;  // its areaFactor is written here
  const double* sums;  // chunks rows of AreaSums
  uint32_t chunks;
  double* scalars;
  Scalars at;
  CostSettings cost;
  TSAH_HD void operator()(uint32_t) const {
    Aabb buffer[kMaxDeviceFrames];
    for (uint32_t f = 0; f < t.frames; ++f) {
      double in = 0.0, le = 0.0;
      for (uint32_t c = 0; c < chunks; ++c) {
        in += sums[std::size_t(c) * 2 * t.frames + f];
        le += sums[std::size_t(c) * 2 * t.frames + t.frames + f];
      }
      scalars[at.innerArea() + f] = in;
      scalars[at.leafArea() + f] = le;
    }
    const Aabb* rootBoxes = boxesOf(t, *t.root, buffer);
    for (uint32_t f = 0; f < t.frames; ++f) scalars[at.rootArea() + f] = rootBoxes[f].area();
    double* frameCost = scalars + at.frameCost();
    scalars[at.cost()] = costWithChange(frameSums(scalars, at, cost), nullptr, frameCost);
    // w_i = (C_i / largest)^k normalized (tsah::temporalWeights).
    double largest = 0.0, total = 0.0, weight[kMaxDeviceFrames];
    for (uint32_t f = 0; f < t.frames; ++f) largest = frameCost[f] > largest ? frameCost[f] : largest;
    for (uint32_t f = 0; f < t.frames; ++f) {
      weight[f] = (cost.k == 0 || !(largest > 0.0)) ? 1.0 : cost::integerPower(frameCost[f] / largest, cost.k);
      total += weight[f];
    }
    if (!(total > 0.0)) {
      for (uint32_t f = 0; f < t.frames; ++f) weight[f] = 1.0;
      total = double(t.frames);
    }
    auto* factor = const_cast<float*>(t.areaFactor);
    for (uint32_t f = 0; f < t.frames; ++f)
      factor[f] = cost::areaFactor(weight[f] / total, scalars[at.rootArea() + f]);
  }
};

struct NodeAreas {
  TreeView t;
  TSAH_HD void operator()(uint32_t n) const {
    Aabb buffer[kMaxDeviceFrames];
    t.area[n] = weighted(t, boxesOf(t, n, buffer));
  }
};

// ---- host side ----
// A tree in the optimizer's numbering (interior nodes first, children before parents), with the
// interior boxes of every frame.
struct NumberedTree {
  std::vector<Links> links;
  std::vector<uint32_t> primIds;
  std::vector<Aabb> innerBoxes;  // innerCount * frames
  uint32_t innerCount = 0, nodeCount = 0, root = 0;
  uint64_t primTotal = 0;
};

// The reachable nodes of a valid tree renumbered, without boxes or primIds (the caller moves the
// tree's primIds: they keep their order). Throws std::invalid_argument for an empty tree.
NumberedTree numberTree(const Bvh& tree);
// The interior boxes of every frame, children before parents on one thread.
std::vector<Aabb> innerBoxesOf(const NumberedTree& tree, const PrimitiveBoxes& prims);
// Node n as a BvhNode (a leaf's links hold its primitive range).
BvhNode nodeOf(const Links& links, bool leaf);
// The topology back as a Bvh without boxes (frameCount 0).
Bvh topologyOf(const std::vector<Links>& links, const std::vector<uint32_t>& primIds, uint32_t root,
               uint32_t innerCount);
// The checks every reinsertion optimizer makes of its input (std::invalid_argument).
void checkReinsertionInput(const Bvh& tree, const PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config,
                           const ParallelReinsertionOptimizer::Parallel& parallel);

// Backend: arrays and data-parallel loops (see reinsertion_emulation.cpp for the simplest one).
//   template <class T> Array<T> (data(), size()); make<T>(count); reserve(array, count) (grows,
//   discarding the contents); upload(array, host pointer, count);
//   download(array, host pointer, count); zero(pointer, bytes); forEach(count, phase);
//   selectFlagged(flags, count, out) -> number of i with flags[i] != 0, written to out ascending;
//   sortDescending(keys, values, count) by key; specializedSearch (which search kernel runs).
template <class Backend>
class ReinsertionRounds {
 public:
  template <class T>
  using Array = typename Backend::template Array<T>;

  ReinsertionRounds(Backend& backend, Bvh tree, const PrimitiveBoxes& prims,
                    const ParallelReinsertionOptimizer::Config& config,
                    const ParallelReinsertionOptimizer::Parallel& parallel)
      : b_(backend), config_(config), parallel_(parallel), prims_(&prims) {
    checkReinsertionInput(tree, prims, config, parallel);
    if (prims.frameCount > kMaxDeviceFrames)
      throw std::invalid_argument("the GPU optimizer takes at most " + std::to_string(kMaxDeviceFrames) +
                                  " representative frames (" + std::to_string(prims.frameCount) + " given)");
    frames_ = prims.frameCount;
    NumberedTree numbered = numberTree(tree);
    numbered.primIds = std::move(tree.primIds);
    tree = Bvh{};
    const uint32_t root = numbered.root;
    numbered.innerBoxes = innerBoxesOf(numbered, prims);
    innerCount_ = numbered.innerCount;
    nodeCount_ = numbered.nodeCount;
    cost_ = {config.cost.ct, config.cost.ci, config.k, innerCount_, numbered.primTotal};
    at_ = {frames_};
    links_ = b_.template make<Links>(nodeCount_);
    b_.upload(links_, numbered.links.data(), nodeCount_);
    primIds_ = b_.template make<uint32_t>(numbered.primIds.size());
    b_.upload(primIds_, numbered.primIds.data(), numbered.primIds.size());
    innerBoxes_ = b_.template make<Aabb>(numbered.innerBoxes.size());
    b_.upload(innerBoxes_, numbered.innerBoxes.data(), numbered.innerBoxes.size());
    numbered = NumberedTree{};
    primBoxes_ = b_.template make<Aabb>(prims.boxes.size());
    b_.upload(primBoxes_, prims.boxes.data(), prims.boxes.size());
    root_ = b_.template make<uint32_t>(1);
    b_.upload(root_, &root, 1);
    area_ = b_.template make<float>(nodeCount_);
    areaFactor_ = b_.template make<float>(frames_);
    scalars_ = b_.template make<double>(at_.size());
    b_.zero(scalars_.data(), scalars_.size() * sizeof(double));
    changedIn_ = b_.template make<uint32_t>(nodeCount_);
    quietSince_ = b_.template make<uint32_t>(nodeCount_);
    b_.zero(changedIn_.data(), nodeCount_ * sizeof(uint32_t));
    b_.zero(quietSince_.data(), nodeCount_ * sizeof(uint32_t));
    flags_ = b_.template make<uint8_t>(nodeCount_);
    taken_ = b_.template make<uint8_t>(nodeCount_);
    owner_ = b_.template make<unsigned long long>(nodeCount_);
    candidates_ = b_.template make<uint32_t>(nodeCount_);
    // The per-move arrays grow to the largest round's needs (reserve), not to the node count.
    const uint32_t chunks = std::max(areaChunks(), (winnerCapacity() + kDeltaChunk - 1) / kDeltaChunk);
    partialA_ = b_.template make<double>(std::size_t(chunks) * 2 * frames_);
    partialB_ = b_.template make<double>((std::size_t(chunks) / kRowsPerThread + 1) * 2 * frames_);
    refresh();
  }

  ReinsertionRoundStats round(bool focused) {
    ReinsertionRoundStats stats;
    ++round_;
    const TreeView t = view();
    // 1-2. candidates and their searches
    const CandidateRule rule{config_.seed, round_, parallel_.candidateFraction, focused, changedIn_.data(),
                             quietSince_.data()};
    b_.forEach(nodeCount_, MarkCandidates{t, rule, flags_.data()});
    const uint32_t candidates = b_.selectFlagged(flags_.data(), nodeCount_, candidates_.data());
    b_.reserve(moves_, candidates);
    b_.reserve(improving_, candidates);
    b_.reserve(status_, candidates);
    if (b_.specializedSearch)
      b_.forEach(candidates, SearchCandidates<true>{t, candidates_.data(), moves_.data(), flags_.data(),
                                                    quietSince_.data(), round_});
    else
      b_.forEach(candidates, SearchCandidates<false>{t, candidates_.data(), moves_.data(), flags_.data(),
                                                     quietSince_.data(), round_});
    const uint32_t improving = b_.selectFlagged(flags_.data(), candidates, improving_.data());
    stats.candidates = candidates;
    stats.improving = improving;
    searches_ += candidates;
    if (improving == 0) return stats;
    // 3. claim passes
    b_.zero(status_.data(), improving);
    b_.zero(taken_.data(), nodeCount_);
    for (uint32_t pass = 0; pass < kClaimPasses; ++pass) {
      b_.zero(owner_.data(), std::size_t(nodeCount_) * sizeof(unsigned long long));
      b_.forEach(improving, ClaimNodes{t, moves_.data(), improving_.data(), status_.data(), owner_.data()});
      b_.forEach(improving, DecideWinners{t, moves_.data(), improving_.data(), status_.data(), owner_.data(), taken_.data()});
      b_.forEach(improving, EliminateLosers{t, moves_.data(), improving_.data(), status_.data(), taken_.data()});
    }
    b_.forEach(improving, FlagWinners{status_.data(), flags_.data()});
    b_.reserve(winners_, std::min(improving, winnerCapacity()));
    const uint32_t winners = b_.selectFlagged(flags_.data(), improving, winners_.data());
    b_.reserve(keys_, winners);
    b_.reserve(slots_, winners);
    b_.reserve(delta_, std::size_t(winners) * frames_);
    b_.reserve(accept_, winners);
    b_.reserve(accepted_, winners);
    b_.reserve(grandparents_, winners);
    stats.winners = winners;
    // 4. exact changes in priority order
    b_.forEach(winners, WinnerKeys{moves_.data(), improving_.data(), winners_.data(), keys_.data(), slots_.data()});
    b_.sortDescending(keys_.data(), slots_.data(), winners);
    b_.forEach(winners, AreaChanges{t, moves_.data(), slots_.data(), delta_.data()});
    // 5. acceptance
    b_.forEach(1, Gradient{scalars_.data(), at_, cost_});
    b_.forEach(winners, LinearAcceptance{delta_.data(), scalars_.data(), at_, accept_.data()});
    const uint32_t chunks = (winners + kDeltaChunk - 1) / kDeltaChunk;
    b_.forEach(chunks, SumAccepted{delta_.data(), accept_.data(), winners, frames_, partialA_.data()});
    uint32_t rows = chunks;
    const double* sums = reduceRows(rows, frames_);
    b_.forEach(1, CommitAccepted{sums, rows, scalars_.data(), at_, cost_});
    double fallback = 0.0;
    b_.download(scalars_, &fallback, 1, at_.fallback());
    if (fallback != 0.0) {
      b_.forEach(1, SerialAcceptance{delta_.data(), winners, accept_.data(), scalars_.data(), at_, cost_});
      ++fallbacks_;
    }
    const uint32_t accepted = b_.selectFlagged(accept_.data(), winners, accepted_.data());
    stats.applied = accepted;
    applied_ += accepted;
    // 6. apply, refit
    b_.forEach(accepted, ApplyMoves{t, moves_.data(), slots_.data(), accepted_.data(), changedIn_.data(), round_,
                                    grandparents_.data()});
    b_.forEach(accepted, RefitMoves{t, moves_.data(), slots_.data(), accepted_.data(), grandparents_.data()});
    return stats;
  }

  // After a round: new weights for k > 0 (k = 0: nothing).
  void endRound() {
    if (config_.k > 0) refresh();
  }

  double cost() {
    double c = 0.0;
    b_.download(scalars_, &c, 1, at_.cost());
    return c;
  }
  std::vector<double> frameCosts() {
    std::vector<double> out(frames_);
    b_.download(scalars_, out.data(), frames_, at_.frameCost());
    return out;
  }
  uint64_t searches() const { return searches_; }
  uint64_t appliedMoves() const { return applied_; }
  uint64_t fallbacks() const { return fallbacks_; }  // rounds that took the serial acceptance

  // The current topology (no boxes).
  Bvh topology() {
    std::vector<Links> links(nodeCount_);
    b_.download(links_, links.data(), nodeCount_, 0);
    std::vector<uint32_t> primIds(primIds_.size());
    b_.download(primIds_, primIds.data(), primIds.size(), 0);
    uint32_t root = 0;
    b_.download(root_, &root, 1, 0);
    return topologyOf(links, primIds, root, innerCount_);
  }

 private:
  uint32_t areaChunks() const { return (nodeCount_ + kAreaChunk - 1) / kAreaChunk; }
  // Reduces the rows x columns partial sums in partialA_ (in order, between partialA_ and
  // partialB_) until at most kRowsPerThread rows are left; returns them, rows updated.
  const double* reduceRows(uint32_t& rows, uint32_t columns) {
    double* in = partialA_.data();
    double* out = partialB_.data();
    while (rows > kRowsPerThread) {
      const uint32_t groups = (rows + kRowsPerThread - 1) / kRowsPerThread;
      b_.forEach(groups, SumRows{in, rows, columns, out});
      rows = groups;
      std::swap(in, out);
    }
    return in;
  }
  // Winners touch at least 4 nodes each, all distinct between winners.
  uint32_t winnerCapacity() const { return nodeCount_ / 4 + 1; }

  TreeView view() {
    return {links_.data(), innerBoxes_.data(), area_.data(), primBoxes_.data(), primIds_.data(), areaFactor_.data(),
            root_.data(),  frames_,            innerCount_,  nodeCount_,        prims_->primCount, false};
  }

  void refresh() {
    const TreeView t = view();
    const uint32_t chunks = areaChunks();
    b_.forEach(chunks, AreaSums{t, partialA_.data()});
    uint32_t rows = chunks;
    const double* sums = reduceRows(rows, 2 * frames_);
    b_.forEach(1, RefreshCosts{t, sums, rows, scalars_.data(), at_, cost_});
    b_.forEach(nodeCount_, NodeAreas{t});
  }

  Backend& b_;
  ParallelReinsertionOptimizer::Config config_;
  ParallelReinsertionOptimizer::Parallel parallel_;
  const PrimitiveBoxes* prims_;
  uint32_t frames_ = 1, innerCount_ = 0, nodeCount_ = 0, round_ = 0;
  CostSettings cost_{};
  Scalars at_{};
  uint64_t searches_ = 0, applied_ = 0, fallbacks_ = 0;
  Array<Links> links_;
  Array<uint32_t> primIds_, root_, changedIn_, quietSince_, candidates_, improving_, winners_, slots_, accepted_,
      grandparents_;
  Array<Aabb> innerBoxes_, primBoxes_;
  Array<float> area_, areaFactor_;
  Array<double> scalars_, delta_, partialA_, partialB_;
  Array<uint8_t> flags_, taken_, status_, accept_;
  Array<unsigned long long> owner_, keys_;
  Array<Move> moves_;
};

// A RoundSession over ReinsertionRounds<Backend>: the GPU session and its emulation.
template <class Backend>
class BackendSession final : public RoundSession {
 public:
  BackendSession(Backend backend, Bvh bvh, const PrimitiveBoxes& prims,
                 const ParallelReinsertionOptimizer::Config& config,
                 const ParallelReinsertionOptimizer::Parallel& parallel)
      : backend_(std::move(backend)),
        prims_(&prims),
        rounds_(std::make_unique<ReinsertionRounds<Backend>>(backend_, std::move(bvh), prims, config, parallel)) {}

  RoundStats round(bool focused = true) override { return rounds_->round(focused); }
  void endRound() override { rounds_->endRound(); }
  double cost() const override { return rounds_->cost(); }
  std::vector<double> frameCostList() const override { return rounds_->frameCosts(); }
  Bvh bvh() const override {
    Bvh out = rounds_->topology();
    refit(out, *prims_);
    return out;
  }
  // The device state is freed before the host computes the boxes: the two are never held together.
  Bvh releaseTree(const LeafCollapser* collapse) override {
    Bvh out = rounds_->topology();
    rounds_.reset();
    refit(out, *prims_);
    return collapse ? collapse->collapse(out) : out;
  }
  uint64_t searches() const override { return rounds_->searches(); }
  uint64_t appliedMoves() const override { return rounds_->appliedMoves(); }
  uint64_t serialAcceptanceRounds() const { return rounds_->fallbacks(); }
  const Backend& backend() const { return backend_; }

 private:
  Backend backend_;
  const PrimitiveBoxes* prims_;
  std::unique_ptr<ReinsertionRounds<Backend>> rounds_;
};

}  // namespace tsah::reinsertion
