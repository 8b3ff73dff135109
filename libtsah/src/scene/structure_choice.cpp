#include "tsah/scene/structure_choice.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>

#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/scene/two_level.hpp"

namespace tsah {

namespace {

// `frames` scene frames evenly spaced over the scene's, the first and the last among them.
std::vector<double> representativeTimes(const anim::SceneSources& scene, uint32_t frames) {
  const std::vector<double> all = scene.frameTimes();
  const std::size_t n = std::clamp<std::size_t>(frames, 1, all.size());
  if (n == 1) return {all.front()};
  std::vector<double> out;
  for (std::size_t j = 0; j < n; ++j) out.push_back(all[(j * (all.size() - 1) + (n - 1) / 2) / (n - 1)]);
  return out;
}

// The numerator of Eq. 1 (cT * interior areas + cI * leaf primitives * areas) of a binned SAH tree
// over `boxes`: its cost in absolute area units, to be divided by the scene box's area.
double sahArea(const std::vector<Aabb>& boxes, const StructureChoiceOptions& options, uint32_t maxLeafSize) {
  if (boxes.empty()) return 0.0;
  BinnedSahBuilder::Config config;
  config.cost = options.cost;
  config.maxLeafSize = maxLeafSize;
  const Bvh tree = BinnedSahBuilder(config).build(boxes);
  return frameCost(tree, 0, options.cost) * double(tree.box(tree.root, 0).area());
}

// Surface area of the parallelepiped the affine `m` makes of `box`: a BLAS's node areas scale
// with it (rays meet the instance's triangles in its own space), not with the axis-aligned world box.
double transformedArea(const Aabb& box, const anim::Matrix4& m) {
  if (box.empty()) return 0.0;
  const std::array<double, 3> extent{double(box.hi.x) - box.lo.x, double(box.hi.y) - box.lo.y, double(box.hi.z) - box.lo.z};
  std::array<std::array<double, 3>, 3> edge;  // the box's edges moved by m's linear part
  for (int a = 0; a < 3; ++a)
    for (int r = 0; r < 3; ++r) edge[a][r] = m[4 * r + a] * extent[a];
  const auto crossLength = [](const std::array<double, 3>& u, const std::array<double, 3>& v) {
    return std::hypot(u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]);
  };
  return 2.0 * (crossLength(edge[0], edge[1]) + crossLength(edge[1], edge[2]) + crossLength(edge[2], edge[0]));
}

bool instanceMoves(const anim::SceneSourceInstance& instance, const anim::Animation& source) {
  return instance.keyed() || (source.keyframeCount() > 1 && instance.time.speed > 0.0);
}

std::string costText(double cost) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g", cost);
  return text;
}

}  // namespace

StructureChoice chooseObjectStructure(const anim::SceneSources& scene, const StructureChoiceOptions& options) {
  if (!scene.flattenedObjects.empty()) throw ConfigError("chooseObjectStructure: the scene is flattened already");
  const auto start = std::chrono::steady_clock::now();
  StructureChoice out;
  const double instanceCost = options.instanceCost >= 0.0 ? options.instanceCost : 2.0 * options.cost.ct + options.cost.ci;
  const std::vector<double> times = representativeTimes(scene, options.frames);
  const uint32_t frames = uint32_t(times.size()), count = uint32_t(scene.instances.size());
  out.frames = frames;

  // Every instance's local and world box at each representative time, and the scene's box there.
  std::map<std::pair<uint32_t, double>, Aabb> localBoxes;
  const auto localBox = [&](uint32_t instance, double t) -> const Aabb& {
    const anim::SceneSourceInstance& i = scene.instances[instance];
    const anim::Animation& source = scene.sourceOf(i);
    const double local = i.localTime(t, source);
    auto [at, added] = localBoxes.try_emplace({i.source, local});
    if (added) at->second = sourceBox(source, local);
    return at->second;
  };
  std::vector<Aabb> worldBoxes(std::size_t(frames) * count);
  std::vector<double> sceneArea(frames);
  for (uint32_t f = 0; f < frames; ++f) {
    Aabb sceneBox;
    for (uint32_t i = 0; i < count; ++i) {
      worldBoxes[std::size_t(f) * count + i] = transformBox(localBox(i, times[f]), scene.instances[i].worldAt(times[f]));
      sceneBox.extend(worldBoxes[std::size_t(f) * count + i]);
    }
    sceneArea[f] = std::max(double(sceneBox.area()), 1e-30);
  }

  // Eq. 1 of a binned SAH tree over a source at one local time (relative to its own root box), as
  // the flattened estimate builds its tree at each frame.
  std::map<std::pair<uint32_t, double>, double> blasCost;
  const auto blasCostOf = [&](uint32_t instance, double t) {
    const anim::SceneSourceInstance& i = scene.instances[instance];
    const anim::Animation& source = scene.sourceOf(i);
    const double local = i.localTime(t, source);
    auto [at, added] = blasCost.try_emplace({i.source, local});
    if (added) {
      const std::vector<Aabb> boxes = triangleBoxes(source.indices(), source.positionsAt(local), 1).boxes;
      const double root = localBox(instance, t).area();
      at->second = root > 0.0 ? sahArea(boxes, options, options.maxLeafSize) / root : 0.0;
    }
    return at->second;
  };

  uint64_t structureTriangles = 0;
  for (const auto& source : scene.sources) structureTriangles += source->triangleCount();
  const double memoryBudget = options.memoryFactor * double(structureTriangles);

  std::vector<std::vector<uint32_t>> instancesOf(scene.description.objects.size());
  for (uint32_t i = 0; i < count; ++i) instancesOf[scene.instances[i].object].push_back(i);
  for (uint32_t o = 0; o < instancesOf.size(); ++o) {
    ObjectStructureChoice c;
    c.object = o;
    c.name = scene.description.objects[o].name;
    c.instances = uint32_t(instancesOf[o].size());
    c.keyed = false;
    for (uint32_t i : instancesOf[o]) {
      c.keyed = c.keyed || scene.instances[i].keyed();
      const anim::Animation& source = scene.sourceOf(scene.instances[i]);
      c.moves = c.moves || instanceMoves(scene.instances[i], source);
      c.flattenedTriangles += source.triangleCount();
    }
    out.objects.push_back(std::move(c));
  }

  // Both estimates of one object (left at -1 for one instance without a path, no instances, or an
  // object past the memory bound: decided without them).
  const auto estimate = [&](ObjectStructureChoice& c) {
    const std::vector<uint32_t>& mine = instancesOf[c.object];
    if (c.single() || mine.empty() || double(c.flattenedTriangles) > memoryBudget) return;
    // Instanced: a tree over the instances' world boxes (the TLAS's share) and each instance's
    // BLAS over its transformed box.
    c.instancedCost = 0.0;
    for (uint32_t f = 0; f < frames; ++f) {
      std::vector<Aabb> boxes;
      double blasArea = 0.0;
      for (uint32_t i : mine) {
        boxes.push_back(worldBoxes[std::size_t(f) * count + i]);
        const anim::SceneSourceInstance& instance = scene.instances[i];
        blasArea += blasCostOf(i, times[f]) * transformedArea(localBox(i, times[f]), instance.worldAt(times[f]));
      }
      // The tree's leaves count cI per instance box; entering an instance costs instanceCost.
      double boxArea = 0.0;
      for (const Aabb& b : boxes) boxArea += b.area();
      const double tlasArea = sahArea(boxes, options, 1) + (instanceCost - options.cost.ci) * boxArea;
      c.instancedCost += (tlasArea + blasArea) / sceneArea[f] / frames;
    }
    // Flattened: a binned SAH tree over the world triangles, built at each frame (once when the
    // object does not move: the same triangles at every frame).
    c.flattenedCost = 0.0;
    std::vector<Aabb> triangles(c.flattenedTriangles);
    std::vector<float> positions;
    double area = 0.0;
    for (uint32_t f = 0; f < frames; ++f) {
      if (f == 0 || c.moves) {
        std::size_t at = 0;
        for (uint32_t i : mine) {
          const anim::SceneSourceInstance& instance = scene.instances[i];
          const anim::Animation& source = scene.sourceOf(instance);
          positions.resize(std::size_t(source.vertexCount()) * 3);
          source.positionsAt(instance.localTime(times[f], source), positions);
          anim::transformPoints(instance.worldAt(times[f]), positions.data(), source.vertexCount());
          triangleBoxes(source.indices(), positions, std::span<Aabb>(triangles).subspan(at, source.triangleCount()));
          at += source.triangleCount();
        }
        area = sahArea(triangles, options, options.maxLeafSize);
      }
      c.flattenedCost += area / sceneArea[f] / frames;
    }
  };

  // The decision: moving objects, then (when none of them is flattened) static ones; among the
  // objects the cost favours, the largest savings first while the memory bound allows.
  const std::string margin = std::to_string(int(std::lround(options.margin * 100.0))) + "%";
  double flattenedTriangles = 0.0;
  const auto decide = [&](bool moving) {
    std::vector<ObjectStructureChoice*> favoured;
    bool any = false;
    for (ObjectStructureChoice& c : out.objects) {
      if (c.moves != moving) continue;
      estimate(c);
      if (c.single()) {
        c.flatten = any = true;
        c.reason = "flattened: one instance without a keyed path (nothing is copied)";
      } else if (c.instancedCost < 0.0) {
        c.reason = c.instances == 0 ? "no instances"
                                    : "instanced: its " + std::to_string(c.flattenedTriangles) +
                                          " flattened triangles would be more than " + costText(options.memoryFactor) +
                                          "x the structure's " + std::to_string(structureTriangles) + " (memory bound)";
      } else if (c.flattenedCost <= (1.0 - options.margin) * c.instancedCost) {
        favoured.push_back(&c);
      } else {
        c.reason = "instanced: flattened cost " + costText(c.flattenedCost) + " is not " + margin + " below " +
                   costText(c.instancedCost);
      }
    }
    std::sort(favoured.begin(), favoured.end(), [](const ObjectStructureChoice* a, const ObjectStructureChoice* b) {
      return a->instancedCost - a->flattenedCost > b->instancedCost - b->flattenedCost;
    });
    for (ObjectStructureChoice* c : favoured) {
      const std::string costs = "flattened cost " + costText(c->flattenedCost) + " against " + costText(c->instancedCost) +
                                " instanced";
      if (flattenedTriangles + double(c->flattenedTriangles) > memoryBudget) {
        c->reason = "instanced (memory bound): " + costs + ", but the flattened triangles would pass " +
                    costText(options.memoryFactor) + "x the structure's " + std::to_string(structureTriangles);
        continue;
      }
      flattenedTriangles += double(c->flattenedTriangles);
      c->flatten = any = true;
      c->reason = "flattened: " + costs;
    }
    return any;
  };
  if (decide(true)) {
    for (ObjectStructureChoice& c : out.objects)
      if (!c.moves)
        c.reason = "instanced: moving objects are flattened (a static one in their source would be refitted every frame)";
  } else {
    decide(false);
  }
  for (const ObjectStructureChoice& c : out.objects)
    if (c.flatten) out.flattenedObjects.push_back(c.object);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace tsah
