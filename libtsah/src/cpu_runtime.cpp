#include "tsah/cpu_runtime.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <thread>

#include "anim/error.hpp"

namespace tsah {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

struct CpuRuntime::Threads {
  explicit Threads(uint32_t n) : count(n), arena(static_cast<int>(n)) {}
  uint32_t count;
  tbb::task_arena arena;
};

CpuRuntime::CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount)
    : CpuRuntime(tree, std::move(indices), vertexCount, Config{}) {}

CpuRuntime::CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount, Config config)
    : indices_(std::move(indices)), vertexCount_(vertexCount) {
  // More workers than hardware threads only oversubscribe (and make TBB warn): cap the count.
  const uint32_t hardware = std::max(1u, std::thread::hardware_concurrency());
  const uint32_t threads = config.threads == 0 ? hardware : std::min(config.threads, hardware);
  threads_ = std::make_unique<Threads>(threads);
  if (indices_.size() % 3 != 0) throw anim::Error("runtime: the index array is not a multiple of 3");
  for (uint32_t v : indices_)
    if (v >= vertexCount_) throw anim::Error("runtime: a triangle refers to a vertex out of range");
  setTree(topologyOf(tree));
  positions_.assign(std::size_t(vertexCount_) * 3, 0.0f);
}

namespace {

const FlatBvh& firstTree(const TreeSet& set) {
  if (set.trees.empty() || set.ranges.size() != set.trees.size())
    throw anim::Error("runtime: the tree set holds no trees (or not one time range per tree)");
  return set.trees.front();
}

}  // namespace

CpuRuntime::CpuRuntime(const TreeSet& set, std::vector<uint32_t> indices, uint32_t vertexCount, Config config)
    : CpuRuntime(firstTree(set), std::move(indices), vertexCount, config) {
  if (set.size() == 1) return;
  for (const FlatBvh& tree : set.trees) setTrees_.push_back(topologyOf(tree));
  setRanges_ = set.ranges;
}

FlatBvh CpuRuntime::topologyOf(const FlatBvh& tree) const {
  if (tree.triangleCount() != triangleCount())
    throw anim::Error("runtime: the tree holds " + std::to_string(tree.triangleCount()) +
                      " triangles, the animation " + std::to_string(triangleCount()));
  // Keep only the first frame's block: update() recomputes the boxes anyway.
  FlatBvh one;
  one.frameCount = 1;
  one.interiorCount = tree.interiorCount;
  one.leafCount = tree.leafCount;
  one.depth = tree.depth;
  one.rootRef = tree.rootRef;
  one.rootCount = tree.rootCount;
  const auto block = tree.frameNodes(0);
  one.nodes.assign(block.begin(), block.end());
  one.rootBoxes = {tree.rootBoxes.empty() ? Aabb{} : tree.rootBoxes[0]};
  one.triIndex = tree.triIndex;
  if (auto problem = validateFlatBvh(one)) throw anim::Error("runtime: invalid tree: " + *problem);
  if (one.depth > kTraversalStackSize)
    throw anim::Error("runtime: tree depth " + std::to_string(one.depth) + " exceeds the traversal stack of " +
                      std::to_string(kTraversalStackSize));
  return one;
}

uint32_t CpuRuntime::selectTreeAt(double time) {
  if (setTrees_.empty()) return 0;
  const uint32_t index = treeIndexAt(setRanges_, time);
  if (index != current_) {
    setTree(setTrees_[index]);
    current_ = index;
  }
  return index;
}

CpuRuntime::~CpuRuntime() = default;

uint32_t CpuRuntime::threadCount() const { return threads_->count; }

void CpuRuntime::parallelFor(std::size_t n, std::size_t grain,
                             const std::function<void(std::size_t, std::size_t)>& body) const {
  if (n == 0) return;
  threads_->arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::max<std::size_t>(1, grain)),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  });
}

void CpuRuntime::setTree(FlatBvh tree) {
  if (tree.depth > kTraversalStackSize)
    throw anim::Error("runtime: tree depth " + std::to_string(tree.depth) + " exceeds the traversal stack of " +
                      std::to_string(kTraversalStackSize));
  tree_ = std::move(tree);
  woop_.resize(tree_.triangleCount());

  // Split the tree into about 8 subtrees per thread (each a contiguous index range in canonical
  // order) so the refit load balances; nodes above them are refitted afterwards.
  subtreeTasks_.clear();
  topNodes_.clear();
  if (tree_.interiorCount == 0) return;
  const auto ends = subtreeEnds(tree_);
  const uint32_t grain = std::max<uint32_t>(64, tree_.interiorCount / (8 * threads_->count));
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    if (ends[i] - i <= grain) {
      subtreeTasks_.push_back({i, ends[i]});
      continue;
    }
    topNodes_.push_back(i);
    const GpuBvhNode& n = tree_.nodes[i];
    for (int32_t ref : {n.ref0, n.ref1})
      if (!isLeafRef(ref)) stack.push_back(static_cast<uint32_t>(ref));
  }
  std::sort(topNodes_.begin(), topNodes_.end(), std::greater<>());
}

void CpuRuntime::setPositions(std::span<const float> positions) {
  if (positions.size() != std::size_t(vertexCount_) * 3)
    throw anim::Error("runtime: got " + std::to_string(positions.size()) + " coordinates, expected " +
                      std::to_string(std::size_t(vertexCount_) * 3));
  positions_.assign(positions.begin(), positions.end());
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
  GpuBvhNode& node = tree_.nodes[i];
  for (int c = 0; c < 2; ++c) {
    const int32_t ref = node.childRef(c);
    const Aabb box = isLeafRef(ref) ? refitLeaf(leafFirstSlot(ref), node.childCount(c))
                                    : tree_.nodes[static_cast<uint32_t>(ref)].bounds();
    node.setChildBox(c, box);
  }
}

void CpuRuntime::refitAndWoop() {
  if (tree_.interiorCount == 0) {
    tree_.rootBoxes[0] = refitLeaf(0, tree_.rootCount);
    return;
  }
  parallelFor(subtreeTasks_.size(), 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      const auto [root, stop] = subtreeTasks_[t];
      for (uint32_t i = stop; i-- > root;) refitNode(i);  // children (larger indices) first
    }
  });
  for (uint32_t i : topNodes_) refitNode(i);
  tree_.rootBoxes[0] = tree_.nodes[0].bounds();
}

void CpuRuntime::update(std::span<const float> positions) {
  setPositions(positions);
  refitAndWoop();
}

CpuRuntime::RebuildTimings CpuRuntime::rebuild(std::span<const float> positions, const TreeBuilder& builder) {
  RebuildTimings timings;
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
  threads_->arena.execute([&] { bvh = builder(boxes); });  // a parallel builder uses our threads
  timings.buildMs = msSince(start);
  start = std::chrono::steady_clock::now();
  if (bvh.primCount() != triangleCount())
    throw anim::Error("runtime: the rebuilt tree holds " + std::to_string(bvh.primCount()) + " triangles, expected " +
                      std::to_string(triangleCount()));
  FlatBvh flat = flattenBvh(bvh);
  if (flat.frameCount != 1) {  // keep frame 0 only
    flat.nodes.resize(flat.interiorCount);
    flat.rootBoxes.resize(1);
    flat.frameCount = 1;
  }
  setTree(std::move(flat));
  setTrees_.clear();  // the rebuilt tree replaces the set
  current_ = 0;
  timings.flattenMs = msSince(start);
  start = std::chrono::steady_clock::now();
  refitAndWoop();
  timings.refitMs = msSince(start);
  return timings;
}

BvhView CpuRuntime::view() const {
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

Aabb CpuRuntime::bounds() const { return tree_.rootBoxes[0]; }

}  // namespace tsah
