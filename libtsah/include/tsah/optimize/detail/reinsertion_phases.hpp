#pragma once
// The phases of a GPU reinsertion round (reinsertion_rounds.hpp): one function object per kernel,
// whose operator()(i) is thread i's work, calling only the shared per-thread arithmetic of
// reinsertion_kernels.hpp. Compiled for the GPU (cuda_kernels/src/reinsertion.cu) and for its host
// emulation (reinsertion_emulation.cpp) alike.
#include <cstdint>

#include "tsah/optimize/detail/reinsertion_kernels.hpp"

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
    for (uint32_t f = 0; f < at.frames; ++f)
      change += scalars[at.gradient() + f] * delta[std::size_t(w) * at.frames + f];
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

// Thread i: refits interior node nodes[i] from its children (one level of the first bottom-up refit:
// its children were refitted by earlier launches).
struct RefitNodes {
  TreeView t;
  const uint32_t* nodes;
  TSAH_HD void operator()(uint32_t i) const {
    Aabb buffer[kMaxDeviceFrames];
    refitNode(t, nodes[i], buffer);
  }
};

struct NodeAreas {
  TreeView t;
  TSAH_HD void operator()(uint32_t n) const {
    Aabb buffer[kMaxDeviceFrames];
    t.area[n] = weighted(t, boxesOf(t, n, buffer));
  }
};

}  // namespace tsah::reinsertion
