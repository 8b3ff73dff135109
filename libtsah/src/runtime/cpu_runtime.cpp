#include "tsah/runtime/cpu_runtime.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "tsah/base/coordinates.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/layout/moving_parts.hpp"
#include "layout/refit_plan.hpp"

namespace tsah {

namespace {

// The smallest task of a moving-only refit, in moving nodes.
constexpr uint32_t kMovingGrain = 16;

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The best supported kernels with nodes of this width, or null.
const WideKernels* kernelsFor(Layout layout, std::optional<SimdIsa> isa) {
  const std::vector<SimdIsa> candidates = isa ? std::vector<SimdIsa>{*isa} : supportedIsas();
  for (auto it = candidates.rbegin(); it != candidates.rend(); ++it) {
    if (!isaSupported(*it)) continue;
    const WideKernels& k = wideKernels(*it);
    if (layout == Layout::Bvh4 ? k.closest4 != nullptr : k.closest8 != nullptr) return &k;
  }
  return nullptr;
}

}  // namespace

bool layoutSupported(Layout layout) {
  return layout == Layout::Bvh2 || kernelsFor(layout, std::nullopt) != nullptr;
}

Layout fastestLayout(std::optional<SimdIsa> isa) {
  // An instruction set the processor lacks is left for the runtime to refuse by name.
  if (isa && !isaSupported(*isa)) isa.reset();
  for (Layout l : {Layout::Bvh8, Layout::Bvh4})
    if (kernelsFor(l, isa)) return l;
  return Layout::Bvh2;
}

struct CpuRuntime::Threads {
  Threads(uint32_t n, bool nestedLoops) : count(n), nested(nestedLoops), arena(static_cast<int>(n)) {}
  uint32_t count;
  bool nested;           // Config::nested: the loops run in the caller's arena, not in `arena`
  tbb::task_arena arena;  // initialized on its first use only
};

template <class F>
void CpuRuntime::inArena(const F& f) const {
  if (threads_->nested)
    f();
  else
    threads_->arena.execute(f);
}

CpuRuntime::CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount)
    : CpuRuntime(tree, std::move(indices), vertexCount, Config{}) {}

CpuRuntime::CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount, Config config)
    : indices_(std::move(indices)), vertexCount_(vertexCount) {
  // More workers than the cores this process may run on (all, or those an MPI rank is bound to)
  // only oversubscribe, and make TBB warn: cap the count.
  const uint32_t hardware = uint32_t(std::max(1, tbb::info::default_concurrency()));
  const uint32_t threads = config.threads == 0 ? hardware : std::min(config.threads, hardware);
  threads_ = std::make_unique<Threads>(threads, config.nested);
  if (indices_.size() % 3 != 0) throw tsah::DataError("runtime: the index array is not a multiple of 3");
  for (uint32_t v : indices_)
    if (v >= vertexCount_) throw tsah::DataError("runtime: a triangle refers to a vertex out of range");
  if (config.movingVertices) {
    const std::vector<uint32_t>& ids = *config.movingVertices;
    for (std::size_t k = 0; k < ids.size(); ++k)
      if (ids[k] >= vertexCount_ || (k > 0 && ids[k] <= ids[k - 1]))
        throw tsah::ConfigError("runtime: the moving vertices must be ascending ids below the vertex count " +
                                std::to_string(vertexCount_));
    movingVertices_ = ids;
  }
  setTree(topologyOf(tree));
  positions_.assign(std::size_t(vertexCount_) * 3, 0.0f);
  info_.layout = config.layout;
  if (config.layout == Layout::Bvh2 && config.triangles != TriangleForm::Woop)
    throw tsah::ConfigError("runtime: the bvh2 layout holds its triangles only as Woop triangles");
  info_.triangles = config.triangles;
  if (config.layout == Layout::Bvh2) {
    info_.interiorNodes = tree_.interiorCount;
    info_.leaves = tree_.leafCount;
    info_.depth = tree_.depth;
    const std::vector<double> costs = frameCosts(unflattenBvh(tree), config.collapse.cost);
    info_.binaryCost = info_.layoutCost = temporalCost(costs, config.collapse.k);
    return;
  }
  kernels_ = kernelsFor(config.layout, config.isa);
  if (!kernels_)
    throw tsah::ConfigError(std::string("runtime: no ") + name(config.layout) + " kernels" +
                      (config.isa ? std::string(" for ") + name(*config.isa) : std::string()) +
                      " run on this processor (bvh8 needs AVX2)");
  info_.isa = kernels_->isa;
  collapse_ = config.collapse;
  setWideTree(unflattenBvh(tree), true);  // every frame block of the tree
}

void CpuRuntime::setWideTree(const Bvh& binary, bool reportCosts) {
  WideCollapser::Config c = collapse_;
  c.width = layoutWidth(info_.layout);
  c.leafPacket = c.width;  // the kernels test a leaf's triangles c.width at a time
  const WideBvh w = WideCollapser(c).collapse(binary);
  info_.binaryCost = reportCosts ? temporalCost(frameCosts(binary, c.cost), c.k) : 0.0;
  info_.layoutCost = reportCosts ? temporalCost(wideFrameCosts(w, c.cost), c.k) : 0.0;
  info_.interiorNodes = w.nodeCount();
  info_.leaves = w.leafCount();
  info_.depth = w.depth();
  if (info_.layout == Layout::Bvh4) {
    wide4_ = std::make_shared<WideTree<4>>(w, indices_, threads_->count, info_.isa, info_.triangles);
    if (movingVertices_) wide4_->setMovingVertices(*movingVertices_, vertexCount_);
  } else {
    wide8_ = std::make_shared<WideTree<8>>(w, indices_, threads_->count, info_.isa, info_.triangles);
    if (movingVertices_) wide8_->setMovingVertices(*movingVertices_, vertexCount_);
  }
  staticRefitted_ = false;
}

namespace {

const FlatBvh& firstTree(const TreeSet& set) {
  if (set.trees.empty() || set.ranges.size() != set.trees.size())
    throw tsah::DataError("runtime: the tree set holds no trees (or not one time range per tree)");
  return set.trees.front();
}

}  // namespace

CpuRuntime::CpuRuntime(const TreeSet& set, std::vector<uint32_t> indices, uint32_t vertexCount, Config config)
    : CpuRuntime(firstTree(set), std::move(indices), vertexCount, config) {
  // Build infos (as read from a file): each tree is collapsed with its own objective, as the GPU
  // runtime does; without them every tree takes config.collapse's.
  const bool ownObjectives = !set.builds.empty();
  if (ownObjectives && set.builds.size() != set.trees.size())
    throw tsah::DataError("runtime: the tree set holds build infos, but not one per tree");
  const WideCollapser::Config given = collapse_;
  const auto collapseWith = [&](uint32_t s) {
    collapse_ = given;
    if (ownObjectives) static_cast<Objective&>(collapse_) = wideCollapseConfig(set.builds[s].objective);
  };
  // Tree 0 was collapsed with config.collapse: again only when its own objective differs.
  const bool recollapseFirst = ownObjectives && info_.layout != Layout::Bvh2 &&
                               !(static_cast<const Objective&>(wideCollapseConfig(set.builds[0].objective)) ==
                                 static_cast<const Objective&>(given));
  if (set.size() == 1) {
    if (recollapseFirst) {
      collapseWith(0);
      setWideTree(unflattenBvh(set.trees[0]), true);
    }
    return;
  }
  for (const FlatBvh& tree : set.trees) setTrees_.push_back(topologyOf(tree));
  setRanges_ = set.ranges;
  if (info_.layout == Layout::Bvh2) return;
  // Collapse every tree of the set now (from all its frame blocks), so a switch costs no collapse.
  LayoutInfo first = info_;
  for (uint32_t s = 0; s < set.size(); ++s) {
    if (s > 0 || recollapseFirst) {
      collapseWith(s);
      setWideTree(unflattenBvh(set.trees[s]), s == 0);
      if (s == 0) first = info_;
    }
    setWide4_.push_back(wide4_);
    setWide8_.push_back(wide8_);
  }
  wide4_ = setWide4_[0];
  wide8_ = setWide8_[0];
  info_ = first;
  collapse_ = given;  // a rebuild collapses with the runtime's own settings
}

FlatBvh CpuRuntime::topologyOf(const FlatBvh& tree) const {
  return runtimeTopology(tree, triangleCount(), kTraversalStackSize, "runtime");
}

uint32_t CpuRuntime::selectTreeAt(double time) {
  if (setTrees_.empty()) return 0;
  const uint32_t index = treeIndexAt(setRanges_, time);
  if (index != current_) {
    clearShutter();
    switchTree(index);
  }
  return index;
}

void CpuRuntime::switchTree(uint32_t index) {
  if (index == current_ || setTrees_.empty()) return;
  setTree(setTrees_[index]);
  if (!setWide4_.empty()) {
    wide4_ = setWide4_[index];
    wide8_ = setWide8_[index];
  }
  current_ = index;
}

CpuRuntime::~CpuRuntime() = default;

uint32_t CpuRuntime::threadCount() const { return threads_->count; }

void CpuRuntime::parallelFor(std::size_t n, std::size_t grain,
                             const std::function<void(std::size_t, std::size_t)>& body) const {
  if (n == 0) return;
  inArena([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::max<std::size_t>(1, grain)),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  });
}

static_assert(kMaxBvhDepth <= kTraversalStackSize, "every tree the library makes must fit the traversal stack");

void CpuRuntime::setTree(FlatBvh tree) {
  if (tree.depth > kTraversalStackSize)
    throw tsah::DataError("runtime: tree depth " + std::to_string(tree.depth) + " exceeds the traversal stack of " +
                          std::to_string(kTraversalStackSize));
  tree_ = std::move(tree);
  woop_.resize(tree_.triangleCount());
  staticRefitted_ = false;

  if (tree_.interiorCount == 0) {
    subtreeTasks_.clear();
    topNodes_.clear();
    return;
  }
  const std::vector<uint32_t> ends = subtreeEnds(tree_);
  const auto interiorChildren = [&](uint32_t i, auto push) {
    for (int32_t ref : {tree_.nodes[i].ref0, tree_.nodes[i].ref1})
      if (!isLeafRef(ref)) push(static_cast<uint32_t>(ref));
  };
  detail::planParallelRefit(ends, threads_->count, interiorChildren, subtreeTasks_, topNodes_);
  if (movingVertices_)
    movingPlan_ = std::make_shared<const detail::MovingRefitPlan>(detail::planMovingRefit(
        ends, threads_->count, interiorChildren,
        findMovingParts(tree_, indices_, *movingVertices_, vertexCount_).nodeMoves, kMovingGrain));
}

void CpuRuntime::checkPositions(std::span<const float> positions) const {
  if (positions.size() != std::size_t(vertexCount_) * 3)
    throw tsah::DataError("runtime: got " + std::to_string(positions.size()) + " coordinates, expected " +
                          std::to_string(std::size_t(vertexCount_) * 3));
  // The limit every imported animation obeys: a NaN or huge coordinate would make every box infinite.
  if (const std::size_t bad = firstBadCoordinate(positions); bad < positions.size())
    throw tsah::DataError("runtime: vertex " + std::to_string(bad / 3) + " " + describeBadCoordinate(positions[bad]));
}

void CpuRuntime::checkMovingPositions(std::span<const float> positions) const {
  if (positions.size() != positions_.size()) checkPositions(positions);  // the count's error
  // firstBadCoordinate's test, inline: a call per vertex would cost more than the test.
  const auto good = [](float x) { return std::fabs(x) <= kMaxCoordinate; };  // NaN fails it too
  for (uint32_t v : *movingVertices_) {
    const float* p = positions.data() + 3 * std::size_t(v);
    if (good(p[0]) && good(p[1]) && good(p[2])) continue;
    const std::size_t bad = firstBadCoordinate(std::span<const float>(p, 3));
    throw tsah::DataError("runtime: vertex " + std::to_string(v) + " " + describeBadCoordinate(p[bad]));
  }
}

void CpuRuntime::setPositions(std::span<const float> positions) {
  checkPositions(positions);
  positions_.assign(positions.begin(), positions.end());
  staticPositionsRead_ = true;
}

Aabb CpuRuntime::refitLeaf(uint32_t firstSlot, uint32_t count) {
  Aabb box;
  const float* p = positions_.data();
  for (uint32_t s = firstSlot; s < firstSlot + count; ++s) {
    const uint32_t* tri = indices_.data() + 3 * std::size_t(tree_.triIndex[s]);
    const Vec3 v0{p[3 * tri[0]], p[3 * tri[0] + 1], p[3 * tri[0] + 2]};
    const Vec3 v1{p[3 * tri[1]], p[3 * tri[1] + 1], p[3 * tri[1] + 2]};
    const Vec3 v2{p[3 * tri[2]], p[3 * tri[2] + 1], p[3 * tri[2] + 2]};
    woop_[s] = makeWoopTriangle(v0, v1, v2);
    box.extend(v0);
    box.extend(v1);
    box.extend(v2);
  }
  return box;
}

void CpuRuntime::refitNode(uint32_t i) {
  refitFlatNode(tree_.frameNodes(0), i, [this](uint32_t first, uint32_t count) { return refitLeaf(first, count); });
}

void CpuRuntime::refitAndWoop(bool movingOnly) {
  const auto parallel = [this](std::size_t n, const std::function<void(std::size_t, std::size_t)>& body) {
    parallelFor(n, 1, body);
  };
  if (wide4_) {
    movingOnly ? wide4_->refitMoving(positions_.data(), parallel) : wide4_->refit(positions_.data(), parallel);
    view4_ = wide4_->view(indices_.data(), positions_.data());
    return;
  }
  if (wide8_) {
    movingOnly ? wide8_->refitMoving(positions_.data(), parallel) : wide8_->refit(positions_.data(), parallel);
    view8_ = wide8_->view(indices_.data(), positions_.data());
    return;
  }
  if (tree_.interiorCount == 0) {
    tree_.rootBoxes[0] = refitLeaf(0, tree_.rootCount);
    return;
  }
  if (movingOnly) {
    const detail::MovingRefitPlan& plan = *movingPlan_;
    parallelFor(plan.taskCount(), 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t t = begin; t < end; ++t)
        for (uint32_t k = plan.taskStart[t + 1]; k-- > plan.taskStart[t];) refitNode(plan.taskNodes[k]);
    });
    for (uint32_t i : plan.top) refitNode(i);
  } else {
    parallelFor(subtreeTasks_.size(), 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t t = begin; t < end; ++t) {
        const auto [root, stop] = subtreeTasks_[t];
        for (uint32_t i = stop; i-- > root;) refitNode(i);  // children (larger indices) first
      }
    });
    for (uint32_t i : topNodes_) refitNode(i);
  }
  tree_.rootBoxes[0] = tree_.nodes[0].bounds();
}

void CpuRuntime::update(std::span<const float> positions) {
  // The moving parts only when the last full refit is this tree's, instant (not a blurred frame's keys).
  lastUpdateMovingOnly_ = staticRefitted_ && !blurred() && movingVertices_.has_value();
  if (!lastUpdateMovingOnly_) {
    checkPositions(positions);
    clearShutter();
    positions_.assign(positions.begin(), positions.end());
    staticPositionsRead_ = true;
    refitAndWoop();
    staticRefitted_ = movingVertices_.has_value();
    return;
  }
  checkMovingPositions(positions);
  for (uint32_t v : *movingVertices_)
    std::copy_n(positions.begin() + 3 * std::ptrdiff_t(v), 3, positions_.begin() + 3 * std::ptrdiff_t(v));
  refitAndWoop(true);
}

CpuRuntime::RebuildTimings CpuRuntime::rebuild(std::span<const float> positions, const TreeBuilder& builder) {
  RebuildTimings timings;
  clearShutter();
  setPositions(positions);
  auto start = std::chrono::steady_clock::now();
  std::vector<Aabb> boxes(triangleCount());
  parallelFor(boxes.size(), 4096, [&](std::size_t begin, std::size_t end) {
    triangleBoxes(std::span<const uint32_t>(indices_).subspan(3 * begin, 3 * (end - begin)), positions_,
                  std::span<Aabb>(boxes).subspan(begin, end - begin));
  });
  timings.boxesMs = msSince(start);
  start = std::chrono::steady_clock::now();
  Bvh bvh;
  inArena([&] { bvh = builder(boxes); });  // a parallel builder uses our threads
  timings.buildMs = msSince(start);
  start = std::chrono::steady_clock::now();
  if (bvh.primCount() != triangleCount())
    throw tsah::DataError("runtime: the rebuilt tree holds " + std::to_string(bvh.primCount()) +
                          " triangles, expected " + std::to_string(triangleCount()));
  FlatBvh flat = flattenBvh(bvh);
  if (flat.frameCount != 1) {  // keep frame 0 only
    flat.nodes.resize(flat.interiorCount);
    flat.rootBoxes.resize(1);
    flat.frameCount = 1;
  }
  setTree(std::move(flat));
  setTrees_.clear();  // the rebuilt tree replaces the set
  setWide4_.clear();
  setWide8_.clear();
  current_ = 0;
  if (info_.layout != Layout::Bvh2) {
    collapse_.k = 0;  // one frame: its weight is 1 whatever k is
    setWideTree(bvh, false);
  } else {
    info_.interiorNodes = tree_.interiorCount;
    info_.leaves = tree_.leafCount;
    info_.depth = tree_.depth;
    info_.binaryCost = info_.layoutCost = 0.0;
  }
  timings.flattenMs = msSince(start);
  start = std::chrono::steady_clock::now();
  refitAndWoop();
  timings.refitMs = msSince(start);
  return timings;
}

Hit CpuRuntime::closestHit(const Ray& ray) const {
  if (blurred()) return closestHit(ray, 1.0f);  // the instant triangles are not kept while blurred
  if (wide8_) return kernels_->closest8(view8_, ray);
  if (wide4_) return kernels_->closest4(view4_, ray);
  return tsah::closestHit(binaryView(), ray);
}

bool CpuRuntime::anyHit(const Ray& ray, AnyHitOrder order) const {
  if (blurred()) return anyHit(ray, 1.0f, order);
  if (wide8_) return kernels_->any8(view8_, ray, order);
  if (wide4_) return kernels_->any4(view4_, ray, order);
  return tsah::anyHit(binaryView(), ray);
}

const FlatBvh& CpuRuntime::tree() const {
  if (info_.layout != Layout::Bvh2) throw tsah::ConfigError("runtime: the binary tree is not kept up to date in a wide layout");
  return tree_;
}

BvhView CpuRuntime::view() const {
  if (info_.layout != Layout::Bvh2) throw tsah::ConfigError("runtime: the binary view is not kept up to date in a wide layout");
  return binaryView();
}

BvhView CpuRuntime::binaryView() const {
  BvhView v;
  v.nodes = tree_.nodes.data();
  v.woop = woop_.data();
  v.triIndex = tree_.triIndex.data();
  v.indices = indices_.data();
  v.positions = positions_.data();
  v.rootRef = tree_.rootRef;
  v.rootCount = tree_.rootCount;
  v.rootBox = tree_.rootBoxes[0];
  return v;
}

Aabb CpuRuntime::bounds() const {
  if (blurred()) return parts_.back().keyRootBoxes.back();
  if (wide4_) return wide4_->bounds();
  if (wide8_) return wide8_->bounds();
  return tree_.rootBoxes[0];
}

}  // namespace tsah
