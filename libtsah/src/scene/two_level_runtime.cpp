#include "tsah/scene/two_level_runtime.hpp"

#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "tsah/base/error.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah {

namespace {

// What the shared traversal loop (detail::traverse) reads of the TLAS: its nodes, and as the
// "triangle" of a slot the instance's BLAS, traced with the ray moved into instance space. The
// frame lives for one ray: hitPrim holds the BLAS triangle of the last accepted slot test, which
// is the final hit (every accepted test shortens tmax, so the last one is the nearest).
template <bool AnyHit>
struct TlasFrame {
  const GpuBvhNode* nodes = nullptr;
  const uint32_t* triIndex = nullptr;  // slot -> instance id
  const Affine3x4* toInstance = nullptr;
  const Aabb* instanceBoxes = nullptr;      // per instance: its world box this frame
  const uint8_t* visible = nullptr;         // per instance: 0 while its world transform is singular
  const CpuRuntime* const* blas = nullptr;  // per instance, traced in its own layout
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;
  Aabb rootBox;
  AnyHitOrder order = AnyHitOrder::FarthestFirst;  // any hit: the BLAS traversals' child order
  mutable uint32_t hitPrim = kNoHit;

  const Aabb& root() const { return rootBox; }
  const GpuBvhNode& node(int32_t ref) const { return nodes[ref]; }
  bool intersectSlot(const Ray& ray, const RayPrep& prep, uint32_t s, float tmax, float& t, float& u, float& v) const {
    const uint32_t instance = triIndex[s];
    // The instance's own box before its transform and BLAS: a leaf of several instances is entered
    // by rays that miss most of them (the test is the TLAS nodes' own, on a box inside theirs).
    float entry;
    if (!visible[instance] || !intersectBox(prep, instanceBoxes[instance], ray.tmin, tmax, entry)) return false;
    const Ray local = rayInInstance(toInstance[instance], ray, tmax);
    if (AnyHit) {  // the loop stops at the first accepted slot: no distance needed
      if (!blas[instance]->anyHit(local, order)) return false;
      t = tmax;
      u = v = 0.0f;
      return true;
    }
    const Hit h = blas[instance]->closestHit(local);
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    hitPrim = h.tri;
    return true;
  }
};

}  // namespace

anim::Matrix4 inverseAffine(const anim::Matrix4& m) {
  // Inverse of the linear part by cofactors, then -L^-1 * translation.
  const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
  const double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
  if (!(det != 0.0) || !std::isfinite(det)) throw DataError("two-level runtime: an instance transform is not invertible");
  const double r = 1.0 / det;
  anim::Matrix4 inv = anim::identityMatrix();
  inv[0] = (e * i - f * h) * r;
  inv[1] = (c * h - b * i) * r;
  inv[2] = (b * f - c * e) * r;
  inv[4] = (f * g - d * i) * r;
  inv[5] = (a * i - c * g) * r;
  inv[6] = (c * d - a * f) * r;
  inv[8] = (d * h - e * g) * r;
  inv[9] = (b * g - a * h) * r;
  inv[10] = (a * e - b * d) * r;
  for (int row = 0; row < 3; ++row)
    inv[4 * row + 3] = -(inv[4 * row] * m[3] + inv[4 * row + 1] * m[7] + inv[4 * row + 2] * m[11]);
  return inv;
}

std::optional<Affine3x4> instanceSpace(const anim::Matrix4& world) {
  const double det = anim::linearDeterminant(world);
  if (!(std::isfinite(det) && det != 0.0)) return std::nullopt;
  const anim::Matrix4 inverse = inverseAffine(world);
  Affine3x4 a;
  for (int i = 0; i < 12; ++i) a.m[i] = float(inverse[i]);
  return a;
}

struct TwoLevelRuntime::Pool {
  explicit Pool(uint32_t n) : arena(static_cast<int>(n)) {}
  tbb::task_arena arena;
};

void TwoLevelRuntime::parallelFor(std::size_t n, std::size_t grain,
                                  const std::function<void(std::size_t, std::size_t)>& body) const {
  if (n == 0) return;
  pool_->arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::max<std::size_t>(1, grain)),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  });
}

TwoLevelRuntime::TwoLevelRuntime(const TwoLevelScene& scene, Config config) : scene_(scene), config_(config) {
  const uint32_t hardware = uint32_t(std::max(1, tbb::info::default_concurrency()));
  pool_ = std::make_unique<Pool>(config.threads == 0 ? hardware : std::min(config.threads, hardware));
  const anim::SceneSources& sources = scene.scene;
  // Each BLAS runtime refits on one thread: the poses are refitted side by side.
  auto blasRuntime = [&](const Blas& blas) {
    const anim::Animation& source = *sources.sources[blas.source];
    CpuRuntime::Config own(1);
    own.layout = config.layout;
    Objective objective = scene.objective;
    objective.k = blas.animated ? objective.k : 0;  // the objective the BLAS was built with
    own.collapse = wideCollapseConfig(objective);
    // A pose is refitted from its source's frames, whose static vertices stay at rest.
    if (!source.allMoving())
      own.movingVertices.emplace(source.movingVertices().begin(), source.movingVertices().end());
    return std::make_unique<CpuRuntime>(
        blas.flat, std::vector<uint32_t>(source.indices().begin(), source.indices().end()), source.vertexCount(), own);
  };
  for (const Blas& blas : scene.blases) {
    if (blas.animated) {
      staticBlas_.push_back(nullptr);
      continue;
    }
    auto runtime = blasRuntime(blas);
    const anim::Animation& source = *sources.sources[blas.source];
    runtime->update(source.positionsAt(source.startTime()));
    ++totalRefits_;
    staticBlas_.push_back(std::move(runtime));
  }
  for (const Pose& pose : scene.poses) {
    poses_.push_back(blasRuntime(scene.blases[pose.blas]));
    poseScratch_.emplace_back(std::size_t(sources.sources[pose.blas]->vertexCount()) * 3);
  }
  poseLocalTime_.assign(poses_.size(), std::numeric_limits<double>::quiet_NaN());  // never refitted
  const uint32_t count = scene.instanceCount();
  toInstance_.resize(count);
  instanceBoxes_.resize(count);
  blas_.resize(count);
  visible_.resize(count);
  tlas_ = runtimeTopology(flattenBvh(scene.tlas), count, kTraversalStackSize, "two-level runtime: TLAS");
  update(scene.frameTimes.empty() ? sources.start : scene.frameTimes.front());
}

TwoLevelRuntime::~TwoLevelRuntime() = default;

const CpuRuntime& TwoLevelRuntime::runtimeOf(uint32_t instance) const {
  const uint32_t pose = scene_.instancePose[instance];
  return pose == kInvalidIndex ? *staticBlas_[scene_.scene.instances[instance].source] : *poses_[pose];
}

const CpuRuntime& TwoLevelRuntime::blasOf(uint32_t instance) const { return runtimeOf(instance); }

void TwoLevelRuntime::update(double sceneTime) {
  time_ = sceneTime;
  const anim::SceneSources& sources = scene_.scene;
  // Poses: the local time of the first instance showing each (all of them show the same).
  std::vector<double> local(poses_.size());
  std::vector<uint32_t> stale;
  for (uint32_t i = 0; i < scene_.instanceCount(); ++i) {
    const uint32_t p = scene_.instancePose[i];
    if (p != kInvalidIndex) local[p] = sources.instances[i].localTime(sceneTime, *sources.sources[scene_.poses[p].blas]);
  }
  for (uint32_t p = 0; p < poses_.size(); ++p)
    if (!(local[p] == poseLocalTime_[p])) stale.push_back(p);
  pool_->arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, stale.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t j = r.begin(); j < r.end(); ++j) {
        const uint32_t p = stale[j];
        sources.sources[scene_.poses[p].blas]->positionsAt(local[p], poseScratch_[p]);
        poses_[p]->update(poseScratch_[p]);
        poseLocalTime_[p] = local[p];
      }
    });
  });
  lastRefits_ = uint32_t(stale.size());
  totalRefits_ += stale.size();

  for (uint32_t i = 0; i < scene_.instanceCount(); ++i) {
    const anim::Matrix4 world = sources.instances[i].worldAt(sceneTime);
    blas_[i] = &runtimeOf(i);
    const std::optional<Affine3x4> space = instanceSpace(world);
    visible_[i] = space.has_value();
    toInstance_[i] = space.value_or(Affine3x4{});
    instanceBoxes_[i] = transformBox(blas_[i]->bounds(), world);  // flat while singular, still a box
  }
  if (config_.tlas == TlasUpdate::Rebuild)
    tlas_ = runtimeTopology(flattenBvh(rebuildTlas(instanceBoxes_, scene_.objective)), scene_.instanceCount(),
                            kTraversalStackSize, "two-level runtime: TLAS");
  refitTlas();
}

void TwoLevelRuntime::refitTlas() {
  refitFlat(tlas_, [&](uint32_t first, uint32_t count) {
    Aabb box;
    for (uint32_t s = first; s < first + count; ++s) box.extend(instanceBoxes_[tlas_.triIndex[s]]);
    return box;
  });
}

template <bool AnyHit>
static TlasFrame<AnyHit> tlasFrame(const FlatBvh& tlas, const std::vector<Affine3x4>& toInstance,
                                   const std::vector<Aabb>& instanceBoxes, const std::vector<uint8_t>& visible,
                                   const std::vector<const CpuRuntime*>& blas) {
  TlasFrame<AnyHit> f;
  f.nodes = tlas.nodes.data();
  f.triIndex = tlas.triIndex.data();
  f.toInstance = toInstance.data();
  f.instanceBoxes = instanceBoxes.data();
  f.blas = blas.data();
  f.visible = visible.data();
  f.rootRef = tlas.rootRef;
  f.rootCount = tlas.rootCount;
  f.rootBox = tlas.rootBoxes[0];
  return f;
}

TwoLevelHit TwoLevelRuntime::closestHit(const Ray& ray) const {
  const TlasFrame<false> frame = tlasFrame<false>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  const Hit h = detail::traverse<false>(frame, ray);
  TwoLevelHit hit;
  if (!h.valid()) return hit;
  hit.t = h.t;
  hit.u = h.u;
  hit.v = h.v;
  hit.instance = h.tri;
  hit.prim = frame.hitPrim;
  return hit;
}

bool TwoLevelRuntime::anyHit(const Ray& ray, AnyHitOrder order) const {
  TlasFrame<true> frame = tlasFrame<true>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  frame.order = order;
  return detail::traverse<true>(frame, ray).valid();
}

uint64_t TwoLevelRuntime::memoryBytes() const {
  uint64_t bytes = 0;
  const auto runtimeBytes = [](const CpuRuntime& r) {
    uint64_t tree = 0;
    if (const WideTree<4>* w = r.wide4())
      tree = w->nodes().size_bytes() + w->packets().size_bytes() + w->triIndex().size_bytes();
    else if (const WideTree<8>* w8 = r.wide8())
      tree = w8->nodes().size_bytes() + w8->packets().size_bytes() + w8->triIndex().size_bytes();
    else
      tree = uint64_t(r.tree().nodes.size()) * sizeof(GpuBvhNode) + r.tree().triIndex.size() * sizeof(uint32_t) +
             r.woop().size() * sizeof(WoopTriangle);
    return tree + r.positions().size() * sizeof(float) + r.indices().size() * sizeof(uint32_t);
  };
  for (const auto& r : staticBlas_)
    if (r) bytes += runtimeBytes(*r);
  for (const auto& r : poses_) bytes += runtimeBytes(*r);
  for (const auto& s : poseScratch_) bytes += s.size() * sizeof(float);
  bytes += tlas_.nodes.size() * sizeof(GpuBvhNode) + tlas_.triIndex.size() * sizeof(uint32_t);
  bytes += toInstance_.size() * sizeof(Affine3x4) + instanceBoxes_.size() * sizeof(Aabb) + blas_.size() * sizeof(const CpuRuntime*);
  return bytes;
}

}  // namespace tsah
