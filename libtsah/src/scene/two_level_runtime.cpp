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
#include "two_level_frame.hpp"
#include "wide_tlas.hpp"

namespace tsah {

anim::Matrix4 inverseAffine(const anim::Matrix4& m) {
  anim::Matrix4 inv = anim::identityMatrix();
  if (!invertAffineRows(m.data(), inv.data()))
    throw DataError("two-level runtime: an instance transform is not invertible");
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

// The TLAS in the wide BLAS layout's width, with the visitor kernels of the BLAS runtimes'
// instruction set.
struct TwoLevelRuntime::WideTop {
  const WideVisitKernels* kernels = nullptr;
  std::optional<detail::WideTlas<4>> tlas4;
  std::optional<detail::WideTlas<8>> tlas8;
  // The views the kernels read, taken after each refit rather than built again for every ray.
  WideView<4> view4;
  WideView<8> view8;
};

struct TwoLevelRuntime::Pool {
  explicit Pool(uint32_t n) : threads(n), arena(static_cast<int>(n)) {}
  uint32_t threads;
  tbb::task_arena arena;
};

uint32_t TwoLevelRuntime::threadCount() const { return pool_->threads; }

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
  // The BLAS runtimes' refits run nested in the pool's arena: the poses are refitted side by side
  // (refitPoses), and the pool's threads share out the parts of their trees. A pose's tree is split
  // for its share of the threads; a static BLAS, refitted alone, for all of them.
  const std::size_t poses = std::max<std::size_t>(1, scene.poses.size());
  const uint32_t poseShare = uint32_t((pool_->threads + poses - 1) / poses);  // at least 1
  auto blasRuntime = [&](const Blas& blas) {
    const anim::Animation& source = *sources.sources[blas.source];
    CpuRuntime::Config own(blas.animated ? poseShare : pool_->threads);
    own.nested = true;
    own.layout = config.layout;
    Objective objective = scene.objective;
    objective.k = blas.animated ? objective.k : 0;  // the objective the BLAS was built with
    own.collapse = wideCollapseConfig(objective);
    if (blas.animated) own.triangles = poseTriangles();
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
    pool_->arena.execute([&] { runtime->update(source.positionsAt(source.startTime())); });
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
  for (std::size_t t = 0; t < scene.tlases.size(); ++t)
    tlasTrees_.push_back(runtimeTopology(flattenBvh(scene.tlases[t].bvh), count, kTraversalStackSize,
                                         "two-level runtime: TLAS " + std::to_string(t)));
  update(scene.frameTimes.empty() ? sources.start : scene.frameTimes.front());
}

TwoLevelRuntime::~TwoLevelRuntime() = default;

const CpuRuntime& TwoLevelRuntime::runtimeOf(uint32_t instance) const {
  const uint32_t pose = scene_.instancePose[instance];
  return pose == kInvalidIndex ? *staticBlas_[scene_.scene.instances[instance].source] : *poses_[pose];
}

const CpuRuntime& TwoLevelRuntime::blasOf(uint32_t instance) const { return runtimeOf(instance); }

std::vector<std::vector<double>> poseLocalTimes(const TwoLevelScene& scene, std::span<const double> times) {
  // The local time of the first instance showing each pose (all of them show the same).
  const anim::SceneSources& sources = scene.scene;
  std::vector<std::vector<double>> local(scene.poses.size(), std::vector<double>(times.size()));
  for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
    const uint32_t p = scene.instancePose[i];
    if (p == kInvalidIndex) continue;
    for (std::size_t k = 0; k < times.size(); ++k)
      local[p][k] = sources.instances[i].localTime(times[k], *sources.sources[scene.poses[p].blas]);
  }
  return local;
}

void TwoLevelRuntime::refitPoses(const std::vector<double>& local) {
  const anim::SceneSources& sources = scene_.scene;
  std::vector<uint32_t> stale;
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
}

void TwoLevelRuntime::update(double sceneTime) {
  clearShutter();
  time_ = sceneTime;
  const anim::SceneSources& sources = scene_.scene;
  const std::vector<std::vector<double>> local = poseLocalTimes(scene_, std::span<const double>(&sceneTime, 1));
  std::vector<double> now(poses_.size());
  for (uint32_t p = 0; p < poses_.size(); ++p) now[p] = local[p][0];
  refitPoses(now);

  for (uint32_t i = 0; i < scene_.instanceCount(); ++i) {
    const anim::Matrix4 world = sources.instances[i].worldAt(sceneTime);
    blas_[i] = &runtimeOf(i);
    const std::optional<Affine3x4> space = instanceSpace(world);
    visible_[i] = space.has_value();
    toInstance_[i] = space.value_or(Affine3x4{});
    instanceBoxes_[i] = transformBox(blas_[i]->bounds(), world);  // flat while singular, still a box
  }
  const bool rebuilt = config_.tlas == TlasUpdate::Rebuild;
  if (rebuilt)
    tlas_ = runtimeTopology(flattenBvh(rebuildTlas(instanceBoxes_, scene_.objective)), scene_.instanceCount(),
                            kTraversalStackSize, "two-level runtime: TLAS");
  else
    selectTlas(sceneTime);
  refitTlas();
  if (config_.layout != Layout::Bvh2 && (rebuilt || !wideTop_)) {  // a new topology: collapsed again
    auto top = std::make_unique<WideTop>();
    top->kernels = &wideVisitKernels(blas_.front()->layoutInfo().isa);
    if (config_.layout == Layout::Bvh4)
      top->tlas4.emplace(tlas_, instanceBoxes_);
    else
      top->tlas8.emplace(tlas_, instanceBoxes_);
    wideTop_ = std::move(top);
  }
  refitWideTlas();
}

void TwoLevelRuntime::selectTlas(double sceneTime) {
  const uint32_t part = scene_.tlasAt(sceneTime);
  if (part == tlasPart_) return;
  tlas_ = tlasTrees_[part];
  tlasPart_ = part;
  wideTop_.reset();  // collapsed again from the new topology by update()
}

void TwoLevelRuntime::refitWideTlas() {
  if (!wideTop_) return;
  if (wideTop_->tlas4) {
    wideTop_->tlas4->refit(instanceBoxes_);
    wideTop_->view4 = wideTop_->tlas4->view();
  }
  if (wideTop_->tlas8) {
    wideTop_->tlas8->refit(instanceBoxes_);
    wideTop_->view8 = wideTop_->tlas8->view();
  }
}

void TwoLevelRuntime::refitTlas() {
  refitFlat(tlas_, [&](uint32_t first, uint32_t count) {
    Aabb box;
    for (uint32_t s = first; s < first + count; ++s) box.extend(instanceBoxes_[tlas_.triIndex[s]]);
    return box;
  });
}

TwoLevelHit TwoLevelRuntime::closestHit(const Ray& ray) const {
  if (wideTop_ && !blurred()) {  // blurred: the instant trace at the close takes the binary TLAS's keys
    const detail::InstanceVisit<false> visit{toInstance_.data(), visible_.data(), blas_.data()};
    const Hit h = wideTop_->tlas8 ? wideTop_->kernels->closest8(wideTop_->view8, ray, visit.visitor())
                                  : wideTop_->kernels->closest4(wideTop_->view4, ray, visit.visitor());
    return detail::twoLevelHit(h, visit);
  }
  const auto frame = detail::tlasFrame<false, false>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  return detail::twoLevelHit(detail::traverse<false>(frame, ray), frame);
}

bool TwoLevelRuntime::anyHit(const Ray& ray, AnyHitOrder order) const {
  if (wideTop_ && !blurred()) {
    const detail::InstanceVisit<true> visit{toInstance_.data(), visible_.data(), blas_.data(), order};
    return wideTop_->tlas8 ? wideTop_->kernels->any8(wideTop_->view8, ray, order, visit.visitor())
                           : wideTop_->kernels->any4(wideTop_->view4, ray, order, visit.visitor());
  }
  auto frame = detail::tlasFrame<true, false>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  frame.order = order;
  return detail::traverse<true>(frame, ray).valid();
}

uint64_t TwoLevelRuntime::memoryBytes() const {
  uint64_t bytes = 0;
  const auto runtimeBytes = [](const CpuRuntime& r) {
    uint64_t tree = 0;
    const auto wideBytes = [](const auto& w) {
      return w.nodes().size_bytes() + w.packets().size_bytes() + w.vertexPackets().size_bytes() +
             w.packetSlots().size_bytes() + w.triIndex().size_bytes();
    };
    if (const WideTree<4>* w = r.wide4())
      tree = wideBytes(*w);
    else if (const WideTree<8>* w8 = r.wide8())
      tree = wideBytes(*w8);
    else
      tree = uint64_t(r.tree().nodes.size()) * sizeof(GpuBvhNode) + r.tree().triIndex.size() * sizeof(uint32_t) +
             r.woop().size() * sizeof(WoopTriangle);
    uint64_t keys = 0;  // a blurred pose's key sets
    for (std::size_t k = 0; k < r.keyTimes().size(); ++k)
      keys += r.keyWideNodes4(k).size_bytes() + r.keyVertexPackets4(k).size_bytes() + r.keyWideNodes8(k).size_bytes() +
              r.keyVertexPackets8(k).size_bytes() + uint64_t(r.motionView().nodeCount) * sizeof(GpuBvhNode) +
              r.positions().size() * sizeof(float);
    return tree + keys + r.positions().size() * sizeof(float) + r.indices().size() * sizeof(uint32_t);
  };
  for (const auto& r : staticBlas_)
    if (r) bytes += runtimeBytes(*r);
  for (const auto& r : poses_) bytes += runtimeBytes(*r);
  for (const auto& s : poseScratch_) bytes += s.size() * sizeof(float);
  bytes += tlas_.nodes.size() * sizeof(GpuBvhNode) + tlas_.triIndex.size() * sizeof(uint32_t);
  for (const FlatBvh& t : tlasTrees_) bytes += t.nodes.size() * sizeof(GpuBvhNode) + t.triIndex.size() * sizeof(uint32_t);
  if (wideTop_) bytes += wideTop_->tlas4 ? wideTop_->tlas4->bytes() : wideTop_->tlas8->bytes();
  bytes += toInstance_.size() * sizeof(Affine3x4) + instanceBoxes_.size() * sizeof(Aabb) + blas_.size() * sizeof(const CpuRuntime*);
  bytes += keyToWorld_.size() * sizeof(Affine3x4) + keyInstanceBoxes_.size() * sizeof(Aabb) +
           keyTlasNodes_.size() * sizeof(GpuBvhNode) + keyTlasRootBoxes_.size() * sizeof(Aabb) + moving_.size();
  return bytes;
}

}  // namespace tsah
