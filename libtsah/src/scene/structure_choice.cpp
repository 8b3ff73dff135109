#include "tsah/scene/structure_choice.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <span>

#include "tsah/base/error.hpp"
#include "tsah/base/parallel_each.hpp"
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

// Values per (source, local time), each computed once however many instances show that pose.
template <class Value>
class PoseTable {
 public:
  using Key = std::pair<uint32_t, double>;
  // Computes value(key) for every key not held yet, concurrently (the builds are independent).
  void fill(const std::vector<Key>& keys, const std::function<Value(const Key&)>& value) {
    std::vector<typename std::map<Key, Value>::iterator> added;
    for (const Key& key : keys) {
      const auto [at, isNew] = values_.try_emplace(key);
      if (isNew) added.push_back(at);
    }
    forEachConcurrently(added.size(), [&](std::size_t j) { added[j]->second = value(added[j]->first); });
  }
  const Value& at(const Key& key) const { return values_.at(key); }

 private:
  std::map<Key, Value> values_;
};

// The flattened triangles' boxes of a few frames are built at once when they take at most this
// many bytes; larger objects take one frame at a time (the memory the sequential estimate needed).
constexpr std::size_t kConcurrentFrameBytes = std::size_t(256) << 20;

// The cost estimates of sets of instances at the representative times, relative to the scene's
// box there (Eq. 1's scale), averaged over the frames.
class Estimator {
 public:
  Estimator(const anim::SceneSources& scene, const StructureChoiceOptions& options)
      : scene_(scene), options_(options), times_(representativeTimes(scene, options.frames)),
        instanceCost_(options.instanceCost >= 0.0 ? options.instanceCost : 2.0 * options.cost.ct + options.cost.ci) {
    const uint32_t count = uint32_t(scene.instances.size());
    std::vector<uint32_t> all(count);
    for (uint32_t i = 0; i < count; ++i) all[i] = i;
    localBoxes_.fill(poseKeys(all), [&](const PoseTable<Aabb>::Key& key) {
      return sourceBox(*scene.sources[key.first], key.second);
    });
    worldBoxes_.resize(std::size_t(frames()) * count);
    for (uint32_t f = 0; f < frames(); ++f) {
      Aabb sceneBox;
      for (uint32_t i = 0; i < count; ++i) {
        Aabb& box = worldBoxes_[std::size_t(f) * count + i];
        box = transformBox(localBox(i, f), scene.instances[i].worldAt(times_[f]));
        sceneBox.extend(box);
      }
      sceneArea_.push_back(std::max(double(sceneBox.area()), 1e-30));
    }
  }

  uint32_t frames() const { return uint32_t(times_.size()); }

  // Two levels: a binned SAH tree over the world boxes of `kept` instances and of the one source
  // `flattened` instances make (cT per interior node, instanceCost per unit of each box's area),
  // plus each kept instance's BLAS cost (a binned SAH tree over its source at its local time) over
  // its transformed box, plus the flattened source's (a binned SAH tree over its world triangles
  // at each frame; once when `flattenedMoves` is false).
  double twoLevelCost(const std::vector<uint32_t>& kept, const std::vector<uint32_t>& flattened, bool flattenedMoves) {
    estimateBlases(kept);
    const std::vector<double> flattenedArea = flattenedAreas(flattened, flattenedMoves);
    std::vector<double> cost(frames(), 0.0);
    forEachConcurrently(frames(), [&](std::size_t f) {
      std::vector<Aabb> boxes;
      double blasArea = 0.0;
      for (uint32_t i : kept) {
        boxes.push_back(worldBox(i, uint32_t(f)));
        blasArea += blasCosts_.at(poseKey(i, uint32_t(f))) *
                    transformedArea(localBox(i, uint32_t(f)), scene_.instances[i].worldAt(times_[f]));
      }
      if (!flattened.empty()) {
        Aabb group;
        for (uint32_t i : flattened) group.extend(worldBox(i, uint32_t(f)));
        boxes.push_back(group);
        blasArea += flattenedArea[f];
      }
      // The tree's leaves count cI per box; entering an instance costs instanceCost.
      double boxArea = 0.0;
      for (const Aabb& b : boxes) boxArea += b.area();
      const double tlasArea = sahArea(boxes, options_, 1) + (instanceCost_ - options_.cost.ci) * boxArea;
      cost[f] = (tlasArea + blasArea) / sceneArea_[f];
    });
    return temporalCost(cost, 0);  // the mean over the frames
  }

  // The BLAS estimates of the poses `instances` show at the representative times, concurrently:
  // what twoLevelCost reads (computed on demand there too).
  void estimateBlases(const std::vector<uint32_t>& instances) {
    blasCosts_.fill(poseKeys(instances), [&](const PoseTable<double>::Key& key) {
      const anim::Animation& source = *scene_.sources[key.first];
      const std::vector<Aabb> boxes = triangleBoxes(source.indices(), source.positionsAt(key.second), 1).boxes;
      const double root = localBoxes_.at(key).area();
      return root > 0.0 ? sahArea(boxes, options_, options_.maxLeafSize) / root : 0.0;
    });
  }

  // One level: a binned SAH tree over the world triangles of `instances`, built at each frame
  // (once when they do not move: the same triangles at every frame).
  double flattenedCost(const std::vector<uint32_t>& instances, bool moves) const {
    const std::vector<double> area = flattenedAreas(instances, moves);
    std::vector<double> cost(frames());
    for (uint32_t f = 0; f < frames(); ++f) cost[f] = area[f] / sceneArea_[f];
    return temporalCost(cost, 0);  // the mean over the frames
  }

 private:
  PoseTable<double>::Key poseKey(uint32_t instance, uint32_t f) const {
    const anim::SceneSourceInstance& i = scene_.instances[instance];
    const anim::Animation& source = scene_.sourceOf(i);
    // A source of one keyframe is the same at every time: one box and one BLAS estimate.
    return {i.source, source.keyframeCount() > 1 ? i.localTime(times_[f], source) : 0.0};
  }
  std::vector<PoseTable<double>::Key> poseKeys(const std::vector<uint32_t>& instances) const {
    std::vector<PoseTable<double>::Key> keys;
    for (uint32_t f = 0; f < frames(); ++f)
      for (uint32_t i : instances) keys.push_back(poseKey(i, f));
    return keys;
  }
  const Aabb& localBox(uint32_t instance, uint32_t f) const { return localBoxes_.at(poseKey(instance, f)); }
  const Aabb& worldBox(uint32_t instance, uint32_t f) const {
    return worldBoxes_[std::size_t(f) * scene_.instances.size() + instance];
  }

  // Eq. 1's numerator of a binned SAH tree over the world triangles of `instances` at every frame.
  std::vector<double> flattenedAreas(const std::vector<uint32_t>& instances, bool moves) const {
    std::vector<double> area(frames(), 0.0);
    if (instances.empty()) return area;
    std::size_t triangles = 0;
    for (uint32_t i : instances) triangles += scene_.sourceOf(scene_.instances[i]).triangleCount();
    const auto areaAt = [&](std::size_t f) {
      std::vector<Aabb> boxes(triangles);
      std::vector<float> positions;
      std::size_t at = 0;
      for (uint32_t i : instances) {
        const anim::SceneSourceInstance& instance = scene_.instances[i];
        const anim::Animation& source = scene_.sourceOf(instance);
        positions.resize(std::size_t(source.vertexCount()) * 3);
        source.positionsAt(instance.localTime(times_[f], source), positions);
        anim::transformPoints(instance.worldAt(times_[f]), positions.data(), source.vertexCount());
        triangleBoxes(source.indices(), positions, std::span<Aabb>(boxes).subspan(at, source.triangleCount()));
        at += source.triangleCount();
      }
      area[f] = sahArea(boxes, options_, options_.maxLeafSize);
    };
    const std::size_t built = moves ? frames() : 1;
    if (built * triangles * sizeof(Aabb) <= kConcurrentFrameBytes) {
      forEachConcurrently(built, areaAt);
    } else {
      for (std::size_t f = 0; f < built; ++f) areaAt(f);
    }
    std::fill(area.begin() + std::ptrdiff_t(built), area.end(), area[0]);
    return area;
  }

  const anim::SceneSources& scene_;
  const StructureChoiceOptions& options_;
  std::vector<double> times_;
  double instanceCost_;
  PoseTable<Aabb> localBoxes_;
  PoseTable<double> blasCosts_;  // Eq. 1 of a source's BLAS at a local time, relative to its box
  std::vector<Aabb> worldBoxes_;  // frame-major
  std::vector<double> sceneArea_;
};

}  // namespace

StructureChoice chooseObjectStructure(const anim::SceneSources& scene, const StructureChoiceOptions& options) {
  if (!scene.flattenedObjects.empty()) throw ConfigError("chooseObjectStructure: the scene is flattened already");
  const auto start = std::chrono::steady_clock::now();
  StructureChoice out;
  Estimator estimator(scene, options);
  out.frames = estimator.frames();
  const uint32_t count = uint32_t(scene.instances.size());

  uint64_t structureTriangles = 0;
  for (const auto& source : scene.sources) structureTriangles += source->triangleCount();
  const double memoryBudget = options.memoryFactor * double(structureTriangles);

  std::vector<std::vector<uint32_t>> instancesOf(scene.description.objects.size());
  for (uint32_t i = 0; i < count; ++i) instancesOf[scene.instances[i].object].push_back(i);
  uint64_t sceneTriangles = 0;
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
    sceneTriangles += c.flattenedTriangles;
    out.objects.push_back(std::move(c));
  }

  // Every estimated object's BLAS poses at once: many small independent builds.
  std::vector<uint32_t> estimated;
  for (const ObjectStructureChoice& c : out.objects)
    if (!c.single() && double(c.flattenedTriangles) <= memoryBudget)
      estimated.insert(estimated.end(), instancesOf[c.object].begin(), instancesOf[c.object].end());
  estimator.estimateBlases(estimated);

  // Both estimates of one object (left at -1 for one instance without a path, no instances, or an
  // object past the memory bound: decided without them).
  const auto estimate = [&](ObjectStructureChoice& c) {
    const std::vector<uint32_t>& mine = instancesOf[c.object];
    if (c.single() || mine.empty() || double(c.flattenedTriangles) > memoryBudget) return;
    c.instancedCost = estimator.twoLevelCost(mine, {}, false);
    c.flattenedCost = estimator.flattenedCost(mine, c.moves);
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
  // Rule 5, after moving objects were flattened: the per-object estimates do not see the kept
  // instances overlapping the flattened source (walkers among buildings: rays then enter both).
  // Weigh the structure so decided against every object flattened into one tree.
  const auto weighWholeScene = [&] {
    std::vector<uint32_t> kept, flattened, all(count);
    for (uint32_t i = 0; i < count; ++i) {
      all[i] = i;
      (out.objects[scene.instances[i].object].flatten ? flattened : kept).push_back(i);
    }
    // Only static kept objects: their copies in one tree are never refitted (a kept moving object
    // would refit every copy, where its instances share their poses' refits).
    double keptTriangles = 0.0;
    bool keptMoves = false;
    for (const ObjectStructureChoice& c : out.objects)
      if (!c.flatten) {
        keptTriangles += double(c.flattenedTriangles);
        keptMoves = keptMoves || c.moves;
      }
    if (kept.empty() || keptMoves || double(sceneTriangles) > memoryBudget ||
        keptTriangles > options.wholeSceneFactor * flattenedTriangles)
      return;
    out.decidedCost = estimator.twoLevelCost(kept, flattened, true);
    out.wholeFlattenedCost = estimator.flattenedCost(all, true);
    const std::string costs = "the whole scene flattened costs " + costText(out.wholeFlattenedCost) + " against " +
                              costText(out.decidedCost) + " for the two levels decided per object";
    // No margin: the moving triangles are copies refitted every frame in either structure, and a
    // flat tree's refit skips its static subtrees; a tie keeps no instances.
    const bool whole = out.wholeFlattenedCost <= out.decidedCost;
    for (ObjectStructureChoice& c : out.objects) {
      if (c.flatten) continue;
      if (whole) {
        c.flatten = true;
        c.reason = "flattened with the whole scene: " + costs;
      } else {
        c.reason += "; " + costs;
      }
    }
  };
  if (decide(true)) {
    for (ObjectStructureChoice& c : out.objects)
      if (!c.moves)
        c.reason = "instanced: moving objects are flattened (a static one in their source would be refitted every frame)";
    weighWholeScene();
  } else {
    decide(false);
  }
  for (const ObjectStructureChoice& c : out.objects)
    if (c.flatten) out.flattenedObjects.push_back(c.object);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace tsah
