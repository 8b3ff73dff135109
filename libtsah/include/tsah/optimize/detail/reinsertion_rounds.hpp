#pragma once
// The GPU form of parallel reinsertion: one round as a fixed sequence of phases, each phase one
// data-parallel loop ("kernel") whose body is a function object of reinsertion_phases.hpp, calling
// only the shared per-thread arithmetic of reinsertion_kernels.hpp. ReinsertionRounds<Backend> runs the sequence;
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
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/optimize/detail/reinsertion_kernels.hpp"
#include "tsah/optimize/detail/reinsertion_phases.hpp"

namespace tsah::reinsertion {

// ---- host side ----
// A tree in the optimizer's numbering (interior nodes first, children before parents).
struct NumberedTree {
  std::vector<Links> links;
  std::vector<uint32_t> primIds;
  uint32_t innerCount = 0, nodeCount = 0, root = 0;
  uint64_t primTotal = 0;
};

// The reachable nodes of a valid tree renumbered, without boxes or primIds (the caller moves the
// tree's primIds: they keep their order). Throws tsah::DataError for an empty tree.
NumberedTree numberTree(const Bvh& tree);
// The interior nodes by height (leaves 0, a node one more than its higher child) into `order`;
// returns the offsets of each height in it (heights 1, 2, ...; one more offset at the end).
std::vector<uint32_t> refitLevels(const NumberedTree& tree, std::vector<uint32_t>& order);
// Node n as a BvhNode (a leaf's links hold its primitive range).
BvhNode nodeOf(const Links& links, bool leaf);
// The topology back as a Bvh without boxes (frameCount 0).
Bvh topologyOf(const std::vector<Links>& links, const std::vector<uint32_t>& primIds, uint32_t root,
               uint32_t innerCount);
// The checks every reinsertion optimizer makes of its input (tsah::ConfigError for the settings,
// tsah::DataError for a tree and boxes that do not match).
void checkReinsertionInput(const Bvh& tree, const PrimitiveBoxes& prims,
                           const ParallelReinsertionOptimizer::Config& config,
                           const ParallelReinsertionOptimizer::Parallel& parallel);

// A backend's make / reserve over its array type, counting the bytes they allocate (allocated):
// the GPU backend reports its buffers, the host emulation the same allocations made on the host.
template <template <class> class ArrayOf>
struct CountedArrays {
  std::size_t allocated = 0;

  template <class T>
  ArrayOf<T> make(std::size_t count) {
    allocated += count * sizeof(T);
    return ArrayOf<T>(count);
  }
  // Grows (discarding the contents) when fewer than `count` elements are held.
  template <class T>
  void reserve(ArrayOf<T>& array, std::size_t count) {
    if (count <= array.size()) return;
    allocated += (count - array.size()) * sizeof(T);
    array = ArrayOf<T>(count);
  }
};

// Backend: arrays and data-parallel loops (see reinsertion_emulation.cpp for the simplest one).
//   template <class T> Array<T> (data(), size()); make<T>(count); reserve(array, count) (grows,
//   discarding the contents: CountedArrays<Array> provides both); upload(array, host pointer, count);
//   download(array, host pointer, count); zero(pointer, bytes); forEach(count, phase);
//   selectFlagged(flags, count, out) -> number of i with flags[i] != 0, written to out ascending;
//   sortDescending(keys, values, count) by key; forEachBalanced(count, phase) for the search (the
//   GPU may run it with persistent threads); specializedSearch (which search kernel runs).
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
      throw tsah::ConfigError("the GPU optimizer takes at most " + std::to_string(kMaxDeviceFrames) +
                              " representative frames (" + std::to_string(prims.frameCount) + " given)");
    frames_ = prims.frameCount;
    NumberedTree numbered = numberTree(tree);
    numbered.primIds = std::move(tree.primIds);
    tree = Bvh{};
    const uint32_t root = numbered.root;
    std::vector<uint32_t> levelOrder;
    const std::vector<uint32_t> levels = refitLevels(numbered, levelOrder);
    innerCount_ = numbered.innerCount;
    nodeCount_ = numbered.nodeCount;
    cost_ = {config.cost.ct, config.cost.ci, config.k, innerCount_, numbered.primTotal};
    at_ = {frames_};
    links_ = b_.template make<Links>(nodeCount_);
    b_.upload(links_, numbered.links.data(), nodeCount_);
    primIds_ = b_.template make<uint32_t>(numbered.primIds.size());
    b_.upload(primIds_, numbered.primIds.data(), numbered.primIds.size());
    innerBoxes_ = b_.template make<Aabb>(std::size_t(innerCount_) * frames_);  // refitted below
    numbered = NumberedTree{};
    primBoxes_ = b_.template make<Aabb>(prims.boxes.size());
    b_.upload(primBoxes_, prims.boxes.data(), prims.boxes.size());
    root_ = b_.template make<uint32_t>(1);
    b_.upload(root_, &root, 1);
    area_ = b_.template make<float>(nodeCount_);
    areaFactor_ = b_.template make<float>(frames_);
    b_.zero(areaFactor_.data(), frames_ * sizeof(float));  // A(N) comes with the first weights
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
    // The interior boxes bottom-up on the device, one launch per level (the candidate list holds
    // the level order meanwhile).
    b_.upload(candidates_, levelOrder.data(), levelOrder.size());
    for (std::size_t level = 0; level + 1 < levels.size(); ++level)
      b_.forEach(levels[level + 1] - levels[level], RefitNodes{view(), candidates_.data() + levels[level]});
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
      b_.forEachBalanced(candidates, SearchCandidates<true>{t, candidates_.data(), moves_.data(), flags_.data(),
                                                    quietSince_.data(), round_});
    else
      b_.forEachBalanced(candidates, SearchCandidates<false>{t, candidates_.data(), moves_.data(), flags_.data(),
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
      b_.forEach(improving,
                 DecideWinners{t, moves_.data(), improving_.data(), status_.data(), owner_.data(), taken_.data()});
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
  Bvh topology() const override { return rounds_->topology(); }
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
