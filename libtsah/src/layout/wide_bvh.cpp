#include "tsah/layout/wide_bvh.hpp"

#include <algorithm>
#include <limits>

#include "tsah/base/assert.hpp"
#include "tsah/base/error.hpp"

namespace tsah {

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Per-frame factors of the weighted area A(B) = sum_i w_i * area(B_i) / S_i; a frame whose root has
// no area counts every node as 1 (see wide_bvh.hpp).
struct AreaWeights {
  std::vector<double> factor;  // w_i / S_i, or 0 for a degenerate frame
  double degenerate = 0.0;     // sum of the weights of the degenerate frames
};

AreaWeights areaWeights(const Bvh& bvh, std::span<const double> weights) {
  AreaWeights a;
  a.factor.assign(bvh.frameCount, 0.0);
  for (uint32_t f = 0; f < bvh.frameCount; ++f) {
    const double rootArea = bvh.box(bvh.root, f).area();
    if (rootArea > 0.0)
      a.factor[f] = weights[f] / rootArea;
    else
      a.degenerate += weights[f];
  }
  return a;
}

// The dynamic programme of wide_bvh.hpp over the binary nodes (indexed by binary node id).
// slots[n * W + i - 1] is the cheapest cost of n's subtree as at most i slots of a parent node.
class CollapsePlan {
 public:
  CollapsePlan(const Bvh& bvh, const WideCollapser::Config& config, const AreaWeights& areas, bool keepBinary)
      : bvh_(bvh), width_(config.width), slots_(bvh.nodes.size() * width_, kInfinity),
        dist_(bvh.nodes.size() * width_, kInfinity), distSplit_(bvh.nodes.size() * width_, 0),
        fewer_(bvh.nodes.size() * width_, 0), asLeaf_(bvh.nodes.size(), 0), count_(bvh.nodes.size(), 0) {
    const double ct = config.cost.ct, ci = config.cost.ci;
    const uint32_t packet = config.leafPacket;
    // Triangle tests of a leaf: one per packet of `packet` triangles (1: Eq. 1's one per triangle).
    const auto tests = [packet](uint32_t count) { return double((count + packet - 1) / packet); };
    for (uint32_t n : childrenFirstOrder(bvh)) {
      const BvhNode& node = bvh.nodes[n];
      double area = areas.degenerate;
      for (uint32_t f = 0; f < bvh.frameCount; ++f) area += areas.factor[f] * bvh.box(n, f).area();
      double* s = &slots_[std::size_t(n) * width_];
      if (node.isLeaf()) {
        count_[n] = node.primCount;
        asLeaf_[n] = 1;
        std::fill(s, s + width_, ci * tests(node.primCount) * area);
        continue;
      }
      count_[n] = count_[node.left] + count_[node.right];
      const double* l = &slots_[std::size_t(node.left) * width_];
      const double* r = &slots_[std::size_t(node.right) * width_];
      double* d = &dist_[std::size_t(n) * width_];
      uint8_t* split = &distSplit_[std::size_t(n) * width_];
      // dist(n, i): the two binary children share at most i slots (each at least one).
      for (uint32_t i = 2; i <= width_; ++i)
        for (uint32_t k = 1; k < i; ++k) {
          const double c = l[k - 1] + r[i - k - 1];
          if (c < d[i - 1]) d[i - 1] = c, split[i - 1] = uint8_t(k);
        }
      const double leaf = !keepBinary && count_[n] <= config.maxLeafSize ? ci * tests(count_[n]) * area : kInfinity;
      const double interior = ct * area + d[width_ - 1];
      asLeaf_[n] = leaf < interior ? 1 : 0;
      s[0] = std::min(leaf, interior);
      uint8_t* fewer = &fewer_[std::size_t(n) * width_];
      for (uint32_t i = 2; i <= width_; ++i) {
        const bool dissolve = !keepBinary && d[i - 1] < s[i - 2];
        s[i - 1] = dissolve ? d[i - 1] : s[i - 2];
        fewer[i - 1] = dissolve ? 0 : 1;
      }
    }
  }

  bool asLeaf(uint32_t n) const { return asLeaf_[n] != 0; }
  double cost(uint32_t n) const { return slots_[std::size_t(n) * width_]; }

  // The binary nodes that become the children of n as a wide interior node.
  void childrenOf(uint32_t n, std::vector<uint32_t>& out) const {
    out.clear();
    const BvhNode& node = bvh_.nodes[n];
    const uint32_t k = distSplit_[std::size_t(n) * width_ + width_ - 1];
    expand(node.left, k, out);
    expand(node.right, width_ - k, out);
  }

 private:
  // Appends the at most i slots that represent n's subtree.
  void expand(uint32_t n, uint32_t i, std::vector<uint32_t>& out) const {
    for (;;) {
      const BvhNode& node = bvh_.nodes[n];
      if (node.isLeaf() || i == 1) {
        out.push_back(n);
        return;
      }
      if (fewer_[std::size_t(n) * width_ + i - 1]) {
        --i;
        continue;
      }
      const uint32_t k = distSplit_[std::size_t(n) * width_ + i - 1];
      expand(node.left, k, out);  // depth bounded by the width: each step has fewer slots
      n = node.right;
      i -= k;
    }
  }

  const Bvh& bvh_;
  uint32_t width_;
  std::vector<double> slots_, dist_;
  std::vector<uint8_t> distSplit_, fewer_, asLeaf_;
  std::vector<uint32_t> count_;
};

// Appends the primitives of n's binary subtree, left to right.
void appendPrims(const Bvh& bvh, uint32_t n, std::vector<uint32_t>& out) {
  std::vector<uint32_t> stack{n};
  while (!stack.empty()) {
    const BvhNode& node = bvh.nodes[stack.back()];
    stack.pop_back();
    if (node.isLeaf()) {
      out.insert(out.end(), bvh.primIds.begin() + node.primBegin, bvh.primIds.begin() + node.primBegin + node.primCount);
    } else {
      stack.push_back(node.right);
      stack.push_back(node.left);
    }
  }
}

WideBvh buildWide(const Bvh& bvh, const CollapsePlan& plan, uint32_t width) {
  WideBvh w;
  w.width = width;
  w.frameCount = bvh.frameCount;
  w.primIds.reserve(bvh.primCount());
  w.rootBoxes.resize(bvh.frameCount);
  for (uint32_t f = 0; f < bvh.frameCount; ++f) w.rootBoxes[f] = bvh.box(bvh.root, f);
  if (plan.asLeaf(bvh.root)) {
    appendPrims(bvh, bvh.root, w.primIds);
    w.rootRef = makeLeafRef(0);
    w.rootCount = w.primCount();
    return w;
  }
  w.rootRef = 0;
  // Depth-first pre-order: an interior node gets its index when it is popped.
  struct Task {
    uint32_t binary;
    uint32_t parentSlot;  // kInvalidIndex for the root
  };
  std::vector<Task> stack{{bvh.root, kInvalidIndex}};
  std::vector<uint32_t> slots;
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    const uint32_t index = w.nodeCount();
    if (task.parentSlot != kInvalidIndex) w.children[task.parentSlot].ref = static_cast<int32_t>(index);
    plan.childrenOf(task.binary, slots);
    const uint32_t first = static_cast<uint32_t>(w.children.size());
    w.nodes.push_back({first, static_cast<uint32_t>(slots.size())});
    w.children.resize(first + slots.size());
    for (uint32_t c = 0; c < slots.size(); ++c) {
      const uint32_t m = slots[c];
      for (uint32_t f = 0; f < bvh.frameCount; ++f) w.childBoxes.push_back(bvh.box(m, f));
      if (plan.asLeaf(m)) {
        const uint32_t begin = w.primCount();
        appendPrims(bvh, m, w.primIds);
        w.children[first + c] = {makeLeafRef(begin), w.primCount() - begin};
      }
    }
    for (uint32_t c = uint32_t(slots.size()); c-- > 0;)
      if (!plan.asLeaf(slots[c])) stack.push_back({slots[c], first + c});
  }
  return w;
}

std::vector<double> normalizedWeights(std::span<const double> weights, uint32_t frames) {
  if (weights.size() != frames)
    throw tsah::ConfigError("wide collapse: " + std::to_string(weights.size()) + " frame weights for " +
                            std::to_string(frames) + " frames");
  double total = 0.0;
  for (double w : weights) {
    if (!(w >= 0.0) || !(w < kInfinity))
      throw tsah::ConfigError("wide collapse: frame weights must be finite and >= 0");
    total += w;
  }
  if (!(total > 0.0)) throw tsah::ConfigError("wide collapse: the frame weights are all zero");
  std::vector<double> out(weights.begin(), weights.end());
  for (double& w : out) w /= total;
  return out;
}

}  // namespace

uint32_t WideBvh::leafCount() const {
  if (rootRef < 0) return 1;
  uint32_t leaves = 0;
  for (const WideChild& c : children) leaves += c.isLeaf() ? 1 : 0;
  return leaves;
}

uint32_t WideBvh::depth() const {
  if (rootRef < 0) return 0;
  std::vector<uint32_t> level(nodes.size(), 0);
  uint32_t deepest = 0;
  for (uint32_t i = 0; i < nodeCount(); ++i)  // pre-order: parents first
    for (uint32_t c = nodes[i].firstChild; c < nodes[i].firstChild + nodes[i].childCount; ++c) {
      if (children[c].isLeaf())
        deepest = std::max(deepest, level[i] + 1);
      else
        level[uint32_t(children[c].ref)] = level[i] + 1;
    }
  return deepest;
}

WideCollapser::WideCollapser(Config config) : config_(config) {
  if (config_.width < 2 || config_.width > kMaxWideWidth)
    throw tsah::ConfigError("wide collapse: the width must be 2 to " + std::to_string(kMaxWideWidth));
  if (config_.maxLeafSize < 1) throw tsah::ConfigError("wide collapse: the maximum leaf size must be at least 1");
  if (config_.leafPacket < 1) throw tsah::ConfigError("wide collapse: the leaf packet must hold at least 1 triangle");
  if (config_.k < 0) throw tsah::ConfigError("wide collapse: the exponent k must be >= 0");
  if (!(config_.cost.ct >= 0.0f) || !(config_.cost.ci >= 0.0f))
    throw tsah::ConfigError("wide collapse: the cost constants must be >= 0");
}

WideBvh WideCollapser::collapse(const Bvh& bvh, std::span<const double> weights, double* weightedCost) const {
  if (bvh.primCount() == 0) throw tsah::DataError("wide collapse: the tree is empty");
  if (auto problem = validate(bvh)) throw tsah::DataError("wide collapse: invalid tree: " + *problem);
  const std::vector<double> w = normalizedWeights(weights, bvh.frameCount);
  const CollapsePlan plan(bvh, config_, areaWeights(bvh, w), false);
  if (weightedCost) *weightedCost = plan.cost(bvh.root);
  WideBvh wide = buildWide(bvh, plan, config_.width);
  TSAH_ASSERT_VALID(validateWide(wide), "wide collapse: the wide tree");
  return wide;
}

WideBvh WideCollapser::collapse(const Bvh& bvh) const {
  const std::vector<double> binaryCosts = frameCosts(bvh, config_.cost);
  const double binaryCost = temporalCost(binaryCosts, config_.k);
  std::vector<double> weights = temporalWeights(binaryCosts, config_.k);
  WideBvh best = collapse(bvh, weights);
  if (config_.k == 0) return best;  // the DP minimised C~^0 itself
  // For k > 0 the weights depend on the tree: re-weight with the wide tree's own frame costs a few
  // times and keep the cheapest C~^k; if none beats the binary tree, keep its shape.
  std::vector<double> costs = wideFrameCosts(best, config_.cost);
  double bestCost = temporalCost(costs, config_.k);
  for (int round = 0; round < 3; ++round) {
    weights = temporalWeights(costs, config_.k);
    WideBvh next = collapse(bvh, weights);
    costs = wideFrameCosts(next, config_.cost);
    const double c = temporalCost(costs, config_.k);
    if (!(c < bestCost)) break;
    best = std::move(next);
    bestCost = c;
  }
  if (bestCost <= binaryCost) return best;
  const std::vector<double> w = normalizedWeights(temporalWeights(binaryCosts, config_.k), bvh.frameCount);
  return buildWide(bvh, CollapsePlan(bvh, config_, areaWeights(bvh, w), true), config_.width);
}

WideCollapser::Config wideCollapseConfig(const Objective& objective, uint32_t width) {
  WideCollapser::Config c;
  static_cast<Objective&>(c) = objective;
  c.width = width;
  c.k = std::max(0, objective.k);
  c.maxLeafSize = std::max(1u, objective.maxLeafSize);
  return c;
}

double wideFrameCost(const WideBvh& wide, uint32_t frame, const CostModel& model) {
  if (frame >= wide.frameCount) throw tsah::ConfigError("wide cost: frame index out of range");
  double inner = 0.0, leaves = 0.0;
  uint64_t innerCount = 0;
  if (wide.rootRef < 0) {
    leaves = double(wide.rootBoxes[frame].area()) * wide.rootCount;
  } else {
    inner = wide.rootBoxes[frame].area();
    innerCount = 1;
    for (uint32_t c = 0; c < wide.children.size(); ++c) {
      const double area = wide.childBox(c, frame).area();
      if (wide.children[c].isLeaf()) {
        leaves += area * wide.children[c].count;
      } else {
        inner += area;
        ++innerCount;
      }
    }
  }
  const double rootArea = wide.rootBoxes[frame].area();
  if (!(rootArea > 0.0)) return double(model.ct) * double(innerCount) + double(model.ci) * double(wide.primCount());
  return (model.ct * inner + model.ci * leaves) / rootArea;
}

std::vector<double> wideFrameCosts(const WideBvh& wide, const CostModel& model) {
  std::vector<double> costs(wide.frameCount);
  for (uint32_t f = 0; f < wide.frameCount; ++f) costs[f] = wideFrameCost(wide, f, model);
  return costs;
}

double wideWeightedCost(const WideBvh& wide, std::span<const double> weights, const CostModel& model) {
  const std::vector<double> w = normalizedWeights(weights, wide.frameCount);
  double sum = 0.0;
  for (uint32_t f = 0; f < wide.frameCount; ++f) sum += w[f] * wideFrameCost(wide, f, model);
  return sum;
}

void refitWide(WideBvh& wide, const PrimitiveBoxes& prims) {
  if (prims.primCount != wide.primCount())
    throw tsah::DataError("wide refit: " + std::to_string(prims.primCount) + " primitive boxes for a tree of " +
                          std::to_string(wide.primCount()));
  const uint32_t frames = prims.frameCount;
  wide.frameCount = frames;
  wide.childBoxes.assign(wide.children.size() * std::size_t(frames), Aabb{});
  wide.rootBoxes.assign(frames, Aabb{});
  auto leafBox = [&](uint32_t first, uint32_t count, uint32_t f) {
    Aabb b;
    for (uint32_t s = first; s < first + count; ++s) b.extend(prims.at(f, wide.primIds[s]));
    return b;
  };
  auto nodeBox = [&](uint32_t n, uint32_t f) {
    Aabb b;
    for (uint32_t c = wide.nodes[n].firstChild; c < wide.nodes[n].firstChild + wide.nodes[n].childCount; ++c)
      b.extend(wide.childBox(c, f));
    return b;
  };
  for (uint32_t f = 0; f < frames; ++f) {
    if (wide.rootRef < 0) {
      wide.rootBoxes[f] = leafBox(0, wide.rootCount, f);
      continue;
    }
    for (uint32_t n = wide.nodeCount(); n-- > 0;)  // children (larger indices) first
      for (uint32_t c = wide.nodes[n].firstChild; c < wide.nodes[n].firstChild + wide.nodes[n].childCount; ++c) {
        const WideChild& child = wide.children[c];
        wide.childBox(c, f) = child.isLeaf() ? leafBox(child.firstPrim(), child.count, f) : nodeBox(uint32_t(child.ref), f);
      }
    wide.rootBoxes[f] = nodeBox(0, f);
  }
}

std::vector<uint32_t> wideSubtreeEnds(const WideBvh& wide) {
  std::vector<uint32_t> end(wide.nodes.size());
  for (uint32_t n = wide.nodeCount(); n-- > 0;) {
    end[n] = n + 1;
    for (uint32_t c = wide.nodes[n].firstChild; c < wide.nodes[n].firstChild + wide.nodes[n].childCount; ++c)
      if (!wide.children[c].isLeaf()) end[n] = std::max(end[n], end[uint32_t(wide.children[c].ref)]);
  }
  return end;
}

std::optional<std::string> validateWide(const WideBvh& wide, const PrimitiveBoxes* prims) {
  const std::size_t frames = wide.frameCount;
  if (wide.width < 2 || wide.width > kMaxWideWidth) return "width " + std::to_string(wide.width) + " out of range";
  if (frames == 0) return std::string("no frames");
  if (wide.childBoxes.size() != wide.children.size() * frames) return std::string("child box count mismatch");
  if (wide.rootBoxes.size() != frames) return std::string("root box count mismatch");
  if (wide.primIds.empty()) return std::string("no primitives");
  std::vector<uint8_t> primSeen(wide.primIds.size(), 0), idSeen(wide.primIds.size(), 0);
  auto claim = [&](uint32_t first, uint32_t count) -> std::optional<std::string> {
    if (count == 0 || first >= wide.primIds.size() || count > wide.primIds.size() - first)
      return "leaf range [" + std::to_string(first) + ", +" + std::to_string(count) + ") out of range";
    for (uint32_t s = first; s < first + count; ++s) {
      if (primSeen[s]++) return "triangle slot " + std::to_string(s) + " in two leaves";
    }
    return std::nullopt;
  };
  if (wide.rootRef < 0) {
    if (!wide.nodes.empty() || !wide.children.empty()) return std::string("a leaf root with interior nodes");
    if (auto p = claim(leafFirstSlot(wide.rootRef), wide.rootCount)) return p;
  } else {
    if (wide.rootRef != 0 || wide.rootCount != 0 || wide.nodes.empty()) return std::string("the root must be node 0");
    std::vector<uint8_t> slotOwned(wide.children.size(), 0), referenced(wide.nodes.size(), 0);
    for (uint32_t n = 0; n < wide.nodeCount(); ++n) {
      const WideNode& node = wide.nodes[n];
      if (n > 0 && !referenced[n]) return "node " + std::to_string(n) + " has no parent before it";
      if (node.childCount < 2 || node.childCount > wide.width)
        return "node " + std::to_string(n) + " has " + std::to_string(node.childCount) + " children";
      if (node.firstChild >= wide.children.size() || node.childCount > wide.children.size() - node.firstChild)
        return "node " + std::to_string(n) + ": children out of range";
      for (uint32_t c = node.firstChild; c < node.firstChild + node.childCount; ++c) {
        if (slotOwned[c]++) return "child slot " + std::to_string(c) + " shared by two nodes";
        const WideChild& child = wide.children[c];
        if (child.isLeaf()) {
          if (auto p = claim(child.firstPrim(), child.count)) return p;
        } else {
          const auto target = uint32_t(child.ref);
          if (child.count != 0 || target <= n || target >= wide.nodeCount())
            return "node " + std::to_string(n) + ": child reference " + std::to_string(child.ref) + " not in pre-order";
          if (referenced[target]++) return "node " + std::to_string(target) + " has two parents";
        }
      }
    }
    for (uint8_t owned : slotOwned)
      if (!owned) return std::string("a child slot belongs to no node");
  }
  for (std::size_t s = 0; s < wide.primIds.size(); ++s) {
    if (!primSeen[s]) return "triangle slot " + std::to_string(s) + " in no leaf";
    const uint32_t id = wide.primIds[s];
    if (id >= wide.primIds.size() || idSeen[id]++) return "primIds is not a permutation";
  }
  if (!prims) return std::nullopt;
  if (prims->primCount != wide.primCount() || prims->frameCount != wide.frameCount)
    return std::string("primitive boxes do not match the tree");
  auto leafInside = [&](const Aabb& box, uint32_t first, uint32_t count, uint32_t f) {
    for (uint32_t s = first; s < first + count; ++s)
      if (!box.contains(prims->at(f, wide.primIds[s]))) return false;
    return true;
  };
  for (uint32_t f = 0; f < wide.frameCount; ++f) {
    if (wide.rootRef < 0) {
      if (!leafInside(wide.rootBoxes[f], 0, wide.rootCount, f)) return "frame " + std::to_string(f) + ": root box";
      continue;
    }
    auto inside = [&](const Aabb& box, uint32_t n) {
      for (uint32_t c = wide.nodes[n].firstChild; c < wide.nodes[n].firstChild + wide.nodes[n].childCount; ++c)
        if (!box.contains(wide.childBox(c, f))) return false;
      return true;
    };
    if (!inside(wide.rootBoxes[f], 0)) return "frame " + std::to_string(f) + ": the root box misses a child";
    for (uint32_t c = 0; c < wide.children.size(); ++c) {
      const WideChild& child = wide.children[c];
      const bool ok = child.isLeaf() ? leafInside(wide.childBox(c, f), child.firstPrim(), child.count, f)
                                     : inside(wide.childBox(c, f), uint32_t(child.ref));
      if (!ok) return "frame " + std::to_string(f) + ": box of child slot " + std::to_string(c) + " misses its contents";
    }
  }
  return std::nullopt;
}

}  // namespace tsah
