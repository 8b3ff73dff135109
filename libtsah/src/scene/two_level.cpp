#include "tsah/scene/two_level.hpp"

#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <tuple>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/base/parallel_each.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/core/instance_transform.hpp"
#include "tsah/core/cost.hpp"
#include "scene/two_level_parts.hpp"

namespace tsah {

namespace {

uint64_t bvhBytes(const Bvh& bvh) {
  return bvh.nodes.size() * sizeof(BvhNode) + bvh.boxes.size() * sizeof(Aabb) + bvh.primIds.size() * sizeof(uint32_t);
}

// The objective's settings for one tree of the structure.
TreeOptions treeOptionsWithK(const TreeOptions& options, int k) {
  TreeOptions own = options;
  own.objective.k = k;
  return own;
}

}  // namespace

Aabb transformBox(const Aabb& box, const anim::Matrix4& m) { return transformBoxRows(box, m.data()); }

Aabb sourceBox(const anim::Animation& source, double localTime) {
  const std::vector<float> p = source.positionsAt(localTime);
  Aabb box;
  for (uint32_t v : source.indices()) box.extend(Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]});
  return box;
}

void assignPoses(const anim::SceneSources& scene, TwoLevelScene& out) {
  // Instances of one animated source with the same time mapping show the same pose.
  std::map<std::tuple<uint32_t, double, double, int>, uint32_t> poseOf;
  for (const anim::SceneSourceInstance& i : scene.instances) {
    if (!out.blases[i.source].animated) {
      out.instancePose.push_back(kInvalidIndex);
      continue;
    }
    const auto key = std::make_tuple(i.source, i.time.offset, i.time.speed, int(i.time.outside));
    const auto [it, added] = poseOf.emplace(key, uint32_t(out.poses.size()));
    if (added) out.poses.push_back({i.source, i.time});
    out.instancePose.push_back(it->second);
  }
}

PrimitiveBoxes instanceBoxesOverFrames(const anim::SceneSources& scene, const TwoLevelScene& out) {
  const uint32_t frames = uint32_t(out.frameTimes.size()), count = uint32_t(scene.instances.size());
  checkFitsInMemory(std::size_t(frames) * count * sizeof(Aabb), scene.description.file,
                    std::to_string(frames) + " frames of " + std::to_string(count) + " instance boxes");
  PrimitiveBoxes boxes;
  boxes.frameCount = frames;
  boxes.primCount = count;
  boxes.boxes.resize(std::size_t(frames) * count);
  // A source's box at one local time is computed once, however many instances show it there.
  std::map<std::pair<uint32_t, double>, Aabb> localBoxes;
  for (uint32_t f = 0; f < frames; ++f)
    for (uint32_t i = 0; i < count; ++i) {
      const anim::SceneSourceInstance& instance = scene.instances[i];
      const anim::Animation& source = scene.sourceOf(instance);
      const double local = out.blases[instance.source].animated ? instance.localTime(out.frameTimes[f], source) : 0.0;
      auto [at, added] = localBoxes.try_emplace({instance.source, local});
      if (added) at->second = sourceBox(source, local);
      boxes.boxes[std::size_t(f) * count + i] = transformBox(at->second, instance.worldAt(out.frameTimes[f]));
    }
  return boxes;
}

void computeLevelCosts(TwoLevelScene& out) {
  for (Blas& blas : out.blases) {
    blas.frameCosts = frameCosts(blas.bvh, out.objective.cost);
    blas.cost = temporalCost(blas.frameCosts, blas.animated ? out.objective.k : 0);
  }
  out.tlasFrameCosts = tlasFrameCosts(out);
  out.tlasCost = temporalCost(out.tlasFrameCosts, out.objective.k);
}

uint32_t instanceTableHash(const anim::SceneSources& scene) {
  std::vector<uint32_t> sources;
  for (const anim::SceneSourceInstance& i : scene.instances) sources.push_back(i.source);
  return topologyHash(sources);
}

Aabb instanceWorldBox(const anim::SceneSources& scene, uint32_t instance, double sceneTime) {
  const anim::SceneSourceInstance& i = scene.instances[instance];
  const anim::Animation& source = scene.sourceOf(i);
  return transformBox(sourceBox(source, i.localTime(sceneTime, source)), i.worldAt(sceneTime));
}

uint64_t TwoLevelScene::blasBytes() const {
  uint64_t bytes = 0;
  for (const Blas& b : blases) bytes += bvhBytes(b.bvh);
  return bytes;
}

uint64_t TwoLevelScene::tlasBytes() const {
  uint64_t bytes = 0;
  for (const TlasTree& t : tlases) bytes += bvhBytes(t.bvh);
  return bytes;
}

uint64_t TwoLevelScene::memoryBytes() const {
  return blasBytes() + tlasBytes() + instanceBoxes.boxes.size() * sizeof(Aabb) +
         scene.instances.size() * (sizeof(anim::SceneSourceInstance) + sizeof(uint32_t)) + poses.size() * sizeof(Pose);
}

Bvh rebuildTlas(std::span<const Aabb> instanceBoxes, const Objective& objective) {
  SweepSahBuilder::Config config;
  config.cost = objective.cost;
  config.maxLeafSize = objective.maxLeafSize;
  return SweepSahBuilder(config).build(instanceBoxes);
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void requireValid(const Bvh& bvh, const PrimitiveBoxes& prims, const std::string& what) {
  if (const auto problem = validate(bvh, &prims)) throw Failure(what + ": invalid tree: " + *problem);
}

namespace {

// Source s's BLAS: its tree only (validated and flattened by the caller).
Blas buildBlas(const anim::SceneSources& scene, uint32_t s, const TreeOptions& options) {
  const anim::Animation& source = *scene.sources[s];
  Blas blas;
  blas.source = s;
  blas.animated = source.keyframeCount() > 1;
  TreeOptions own = treeOptionsWithK(options, blas.animated ? options.objective.k : 0);
  own.binnedInitialTree = own.binnedInitialTree || !blas.animated;  // static: often millions of triangles
  OptimizedTree tree = optimizeAnimation(source, own);
  blas.info = tree.info;
  blas.bvh = std::move(tree.bvh);
  return blas;
}

}  // namespace

TwoLevelScene buildTwoLevelScene(anim::SceneSources scene, const TreeOptions& options, const TlasOptions& tlas) {
  options.validate();
  tlas.validate();
  if (options.method != Method::TSah)
    throw ConfigError(std::string("method: a two-level scene builds T-SAH trees, not ") + name(options.method));
  if (scene.instances.empty()) throw DataError(scene.description.file + ": the scene has no instances");
  TwoLevelScene out;
  out.objective = options.objective;

  // One BLAS per source, in the source's own time, the sources concurrently (each tree is the same
  // however the threads are shared). With the GPU optimizer too: a source's host work (its initial
  // tree, the collapse after the optimizer) overlaps the others' device work, which the device
  // runs one launch after another.
  auto phase = std::chrono::steady_clock::now();
  out.blases.resize(scene.sources.size());
  // The callbacks see one message at a time, as from one build.
  TreeOptions shared = options;
  std::mutex callbackMutex;
  if (options.progress)
    shared.progress = [&](const std::string& message) {
      const std::lock_guard<std::mutex> lock(callbackMutex);
      options.progress(message);
    };
  if (options.batchProgress)
    shared.batchProgress = [&](const InsertionOptimizer::BatchRecord& record) {
      const std::lock_guard<std::mutex> lock(callbackMutex);
      options.batchProgress(record);
    };
  forEachConcurrently(scene.sources.size(), [&](std::size_t s) { out.blases[s] = buildBlas(scene, uint32_t(s), shared); });
  out.buildPhases.push_back({"blas", secondsSince(phase)});

  // Each BLAS checked against its source's boxes and flattened: independent, so concurrently.
  phase = std::chrono::steady_clock::now();
  forEachConcurrently(out.blases.size(), [&](std::size_t s) {
    Blas& blas = out.blases[s];
    const anim::Animation& source = *scene.sources[s];
    const std::string what = scene.description.file + ": source " + std::to_string(s) + " (" + source.name() + ")";
    requireValid(blas.bvh, representativeBoxes(source, framesFor(source, options.frames)), what);
    blas.flat = flattenBvh(blas.bvh);
  });
  out.buildPhases.push_back({"check", secondsSince(phase)});

  phase = std::chrono::steady_clock::now();
  assignPoses(scene, out);
  out.frameTimes = scene.frameTimes();
  out.instanceBoxes = instanceBoxesOverFrames(scene, out);
  out.buildPhases.push_back({"instances", secondsSince(phase)});
  phase = std::chrono::steady_clock::now();
  buildTlasTrees(scene, out, options, tlas);
  out.buildPhases.push_back({"tlas", secondsSince(phase)});
  phase = std::chrono::steady_clock::now();
  computeLevelCosts(out);
  out.buildPhases.push_back({"costs", secondsSince(phase)});
  out.scene = std::move(scene);
  return out;
}

TwoLevelScene loadTwoLevelScene(const std::string& path, const anim::LoadOptions& load, const TreeOptions& options,
                                const TlasOptions& tlas) {
  options.validate();
  tlas.validate();
  return buildTwoLevelScene(anim::loadSceneSources(path, load), options, tlas);
}

}  // namespace tsah
