// The visitor kernels (tsah/layout/wide_visit.hpp) of every instruction set and width this machine
// runs, on trees of random boxes whose leaf children are the boxes themselves, against brute force:
// every item whose box the ray enters is visited once (no item twice, none that does not exist);
// closest hit returns the nearest accepted item and stops short of farther ones; any hit answers
// whether one is accepted, in both child orders, and stops at the first.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "tsah/core/ray.hpp"
#include "tsah/layout/wide_visit.hpp"

namespace {

using tsah::Aabb;
using tsah::Vec3;

// A tree over boxes[first, first + count): up to N items as leaf children, else N groups, each a
// leaf child when it holds one item and a node otherwise. Children come after their parent.
template <uint32_t N>
int32_t buildBoxTree(std::vector<tsah::WideSoaNode<N>>& nodes, const std::vector<Aabb>& boxes, uint32_t first,
                     uint32_t count) {
  const uint32_t index = uint32_t(nodes.size());
  nodes.emplace_back();
  tsah::WideSoaNode<N> node{};
  for (uint32_t c = 0; c < N; ++c) node.setChildBox(c, Aabb{});
  const uint32_t groups = std::min(count, N);
  uint32_t at = first;
  for (uint32_t g = 0; g < groups; ++g) {
    const uint32_t size = count / groups + (g < count % groups ? 1 : 0);
    Aabb box;
    for (uint32_t i = at; i < at + size; ++i) box.extend(boxes[i]);
    node.setChildBox(g, box);
    if (size == 1) {
      node.ref[g] = tsah::makeLeafRef(at);
      node.count[g] = 1;
    } else {
      node.ref[g] = buildBoxTree(nodes, boxes, at, size);
    }
    at += size;
  }
  nodes[index] = node;
  return int32_t(index);
}

// The items are the boxes: an item is hit at its box's entry distance (tsah::intersectBox). Records
// every visit; `accept` false: no item is ever hit (every entered item must then be visited).
struct BoxVisit {
  const std::vector<Aabb>* boxes = nullptr;
  bool accept = true;
  mutable std::vector<uint32_t> visited;

  static bool visit(const void* context, uint32_t item, const tsah::Ray& ray, float& tmax, tsah::Hit& hit) {
    const BoxVisit& c = *static_cast<const BoxVisit*>(context);
    c.visited.push_back(item);
    float entry;
    if (!c.accept || !tsah::intersectBox(tsah::prepareSlabs(ray), (*c.boxes)[item], ray.tmin, tmax, entry) ||
        !(entry < tmax))
      return false;
    tmax = entry;
    hit = {entry, 0.0f, 0.0f, item};
    return true;
  }
  tsah::WideLeafVisitor visitor() const { return {this, &BoxVisit::visit}; }
};

template <uint32_t N, class Closest, class Any>
void expectBruteForce(Closest closest, Any any, const char* what) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (const uint32_t count : {1u, 2u, N, N + 1, 37u, 300u}) {
    std::vector<Aabb> boxes(count);
    for (Aabb& b : boxes) {
      const Vec3 c{unit(rng) * 10, unit(rng) * 10, unit(rng) * 10};
      const Vec3 h{unit(rng) * 0.8f + 0.05f, unit(rng) * 0.8f + 0.05f, unit(rng) * 0.8f + 0.05f};
      b.lo = c - h;
      b.hi = c + h;
    }
    std::vector<tsah::WideSoaNode<N>> nodes;
    tsah::WideView<N> view;
    if (count == 1) {  // a leaf root: one item
      view.rootRef = tsah::makeLeafRef(0);
      view.rootCount = 1;
      view.rootBox = boxes[0];
    } else {
      view.rootRef = buildBoxTree<N>(nodes, boxes, 0, count);
      view.nodes = nodes.data();
      view.rootBox = nodes[0].bounds();
    }
    for (int r = 0; r < 300; ++r) {
      tsah::Ray ray;
      ray.org = {unit(rng) * 14 - 2, unit(rng) * 14 - 2, unit(rng) * 14 - 2};
      ray.dir = Vec3{unit(rng) * 10, unit(rng) * 10, unit(rng) * 10} - ray.org;
      ray.tmin = 0.0f;
      ray.tmax = r % 3 == 0 ? 0.3f : 1e30f;  // some short rays, as ambient occlusion's
      const tsah::RayPrep prep = tsah::prepareSlabs(ray);
      std::vector<uint32_t> entered;
      float nearest = ray.tmax;
      uint32_t nearestItem = tsah::kNoHit;
      for (uint32_t i = 0; i < count; ++i) {
        float entry;
        if (!tsah::intersectBox(prep, boxes[i], ray.tmin, ray.tmax, entry)) continue;
        entered.push_back(i);
        if (entry < nearest) nearest = entry, nearestItem = i;
      }
      const std::string where = std::string(what) + " N " + std::to_string(N) + " items " + std::to_string(count) +
                                " ray " + std::to_string(r);
      // Nothing accepted: every entered item visited, each at most once.
      BoxVisit none{&boxes, false, {}};
      EXPECT_FALSE(closest(view, ray, none.visitor()).valid()) << where;
      std::vector<uint32_t> seen = none.visited;
      std::sort(seen.begin(), seen.end());
      EXPECT_EQ(std::adjacent_find(seen.begin(), seen.end()), seen.end()) << where << ": an item visited twice";
      EXPECT_TRUE(std::includes(seen.begin(), seen.end(), entered.begin(), entered.end())) << where;
      EXPECT_TRUE(seen.empty() || seen.back() < count) << where;
      for (const tsah::AnyHitOrder order : {tsah::AnyHitOrder::FarthestFirst, tsah::AnyHitOrder::TreeOrder}) {
        BoxVisit anyNone{&boxes, false, {}};
        EXPECT_FALSE(any(view, ray, order, anyNone.visitor())) << where;
        std::sort(anyNone.visited.begin(), anyNone.visited.end());
        EXPECT_TRUE(std::includes(anyNone.visited.begin(), anyNone.visited.end(), entered.begin(), entered.end()))
            << where;
        BoxVisit anyAccept{&boxes, true, {}};
        EXPECT_EQ(any(view, ray, order, anyAccept.visitor()), nearestItem != tsah::kNoHit) << where;
        if (nearestItem != tsah::kNoHit) {  // stopped at the first accepted item
          float entry;
          const uint32_t last = anyAccept.visited.back();
          EXPECT_TRUE(tsah::intersectBox(prep, boxes[last], ray.tmin, ray.tmax, entry) && entry < ray.tmax) << where;
        }
      }
      // Accepted: the nearest entry (a tie may name another item at the same distance).
      BoxVisit all{&boxes, true, {}};
      const tsah::Hit hit = closest(view, ray, all.visitor());
      ASSERT_EQ(hit.valid(), nearestItem != tsah::kNoHit) << where;
      if (hit.valid()) {
        EXPECT_EQ(hit.t, nearest) << where;
      }
    }
    // A NaN or infinite origin or direction enters nothing (its NaN slab distances would be
    // dropped by the node test's max and min, entering unused slots).
    const float nan = std::nanf(""), inf = std::numeric_limits<float>::infinity();
    for (const float bad : {nan, inf}) {
      for (int axis = 0; axis < 6; ++axis) {
        tsah::Ray ray{{5, 5, 5}, 0.0f, {0.3f, -1.0f, 0.2f}, 1e30f};
        (axis < 3 ? ray.org : ray.dir)[axis % 3] = bad;
        const std::string where = std::string(what) + " N " + std::to_string(N) + " items " + std::to_string(count) +
                                  " bad component " + std::to_string(axis);
        BoxVisit all{&boxes, true, {}};
        EXPECT_FALSE(closest(view, ray, all.visitor()).valid()) << where;
        EXPECT_FALSE(any(view, ray, tsah::AnyHitOrder::TreeOrder, all.visitor())) << where;
        EXPECT_TRUE(all.visited.empty()) << where;
      }
    }
  }
}

TEST(WideVisit, EveryKernelVisitsWhatBruteForceEntersAndReturnsTheNearest) {
  uint32_t tested = 0;
  for (const tsah::SimdIsa isa : tsah::supportedIsas()) {
    const tsah::WideVisitKernels& k = tsah::wideVisitKernels(isa);
    ASSERT_NE(k.closest4, nullptr);
    ASSERT_NE(k.any4, nullptr);
    expectBruteForce<4>(k.closest4, k.any4, tsah::name(isa));
    ++tested;
    if (k.closest8 == nullptr) continue;  // sse: 4-wide only
    ASSERT_NE(k.any8, nullptr);
    expectBruteForce<8>(k.closest8, k.any8, tsah::name(isa));
    ++tested;
  }
  EXPECT_GT(tested, 0u);  // sse runs on every x86-64
}

}  // namespace
