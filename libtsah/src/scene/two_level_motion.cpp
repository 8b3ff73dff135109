// TwoLevelRuntime's motion blur (docs/motion-blur.md, "Two-level scenes"): per key of a shutter the
// instances' world matrices (in float), the poses' BLAS (CpuRuntime::updateShutter with the same
// key fractions), the instances' key boxes and the TLAS refitted from them; a ray traces the TLAS
// with its boxes lerped at the ray's time, a moving instance with its matrix lerped and inverted
// there, and the BLAS at the same time.
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "two_level_frame.hpp"

namespace tsah {

namespace {

Affine3x4 floatRows(const anim::Matrix4& m) {
  Affine3x4 a;
  for (int i = 0; i < 12; ++i) a.m[i] = float(m[i]);
  return a;
}

// The union of a BLAS runtime's root boxes over its keys (its bounds when it is not blurred).
Aabb keysUnion(const CpuRuntime& blas) {
  if (!blas.blurred()) return blas.bounds();
  Aabb u;
  const MotionBvhView& view = blas.motionView();
  for (uint32_t k = 0; k < view.keyCount; ++k) u.extend(view.keyRootBoxes[k]);
  return u;
}

}  // namespace

// The row's magnitude bound A = |m_r3| + sum_j |m_rj| * max |u_j| bounds every term of the world
// coordinate m_r . p of a point p in u; the pad of A covers the rounding of the matrix lerp, the
// vertex lerp and the product (docs/motion-blur.md derives it).
Aabb instanceKeyBox(const Aabb& u, const Affine3x4& m) {
  if (u.empty()) return u;
  double rows[12];
  for (int i = 0; i < 12; ++i) rows[i] = double(m.m[i]);
  Aabb box = transformBoxRows(u, rows);
  double magnitude[3];
  for (int j = 0; j < 3; ++j) magnitude[j] = std::max(std::fabs(double(u.lo[j])), std::fabs(double(u.hi[j])));
  for (int r = 0; r < 3; ++r) {
    double a = std::fabs(rows[4 * r + 3]);
    for (int j = 0; j < 3; ++j) a += std::fabs(rows[4 * r + j]) * magnitude[j];
    const float pad = motion::lerpPad(std::nextafter(float(a), std::numeric_limits<float>::infinity()));
    box.lo[r] -= pad;
    box.hi[r] += pad;
  }
  return box;
}

// What moves: an instance whose float matrix differs between keys, a pose whose local time does.
ShutterMotion shutterMotion(const TwoLevelScene& scene, std::span<const double> keys) {
  const std::size_t keyCount = keys.size();
  const uint32_t count = scene.instanceCount();
  ShutterMotion m;
  m.toWorld.resize(keyCount * count);
  m.movingInstances.assign(count, 0);
  for (uint32_t i = 0; i < count; ++i)
    for (std::size_t k = 0; k < keyCount; ++k) {
      m.toWorld[k * count + i] = floatRows(scene.scene.instances[i].worldAt(keys[k]));
      if (k > 0 && std::memcmp(&m.toWorld[k * count + i], &m.toWorld[i], sizeof(Affine3x4)) != 0)
        m.movingInstances[i] = 1;
      m.anyMoves = m.anyMoves || m.movingInstances[i];
    }
  m.poseLocal = poseLocalTimes(scene, keys);
  m.movingPoses.assign(scene.poses.size(), 0);
  for (std::size_t p = 0; p < scene.poses.size(); ++p)
    for (std::size_t k = 1; k < keyCount; ++k)
      if (!(m.poseLocal[p][k] == m.poseLocal[p][0])) m.movingPoses[p] = 1;
  for (uint8_t moves : m.movingPoses) m.anyMoves = m.anyMoves || moves;
  return m;
}

void TwoLevelRuntime::clearShutter() {
  keyTimes_.clear();
  keySceneTimes_.clear();
  keyToWorld_.clear();
  keyInstanceBoxes_.clear();
  keyTlasNodes_.clear();
  keyTlasRootBoxes_.clear();
  moving_.clear();
}

void TwoLevelRuntime::updateShutter(double openTime, double closeTime) {
  if (!(std::isfinite(openTime) && std::isfinite(closeTime) && openTime <= closeTime))
    throw ConfigError("two-level runtime: a shutter needs finite times with open <= close, got [" +
                      std::to_string(openTime) + ", " + std::to_string(closeTime) + "]");
  const std::vector<double> keys = motion::shutterKeys(scene_.frameTimes, openTime, closeTime);
  if (keys.size() < 2) {
    update(openTime);
    return;
  }
  const std::vector<float> fractions = motion::keyFractions(keys);
  const std::size_t keyCount = keys.size();
  const uint32_t count = scene_.instanceCount();
  const anim::SceneSources& sources = scene_.scene;
  ShutterMotion moves = shutterMotion(scene_, keys);
  if (!moves.anyMoves) {  // nothing moves: the instant at the open
    update(openTime);
    return;
  }
  std::vector<Affine3x4>& toWorld = moves.toWorld;
  const std::vector<std::vector<double>>& local = moves.poseLocal;
  const std::vector<uint8_t>& poseMoves = moves.movingPoses;

  clearShutter();
  time_ = closeTime;
  // Poses: a moving one refitted at every key (its runtime reuses keys of its previous shutter), a
  // still one as update() refits it.
  std::vector<uint32_t> stale;
  for (uint32_t p = 0; p < poses_.size(); ++p)
    if (poseMoves[p] || !(local[p][0] == poseLocalTime_[p])) stale.push_back(p);
  try {
    parallelFor(stale.size(), 1, [&](std::size_t j0, std::size_t j1) {
      for (std::size_t j = j0; j < j1; ++j) {
        const uint32_t p = stale[j];
        const anim::Animation& source = *sources.sources[scene_.poses[p].blas];
        if (!poseMoves[p]) {
          source.positionsAt(local[p][0], poseScratch_[p]);
          poses_[p]->update(poseScratch_[p]);
          poseLocalTime_[p] = local[p][0];
          continue;
        }
        poseLocalTime_[p] = std::numeric_limits<double>::quiet_NaN();  // blurred: the next update refits
        std::vector<std::vector<float>> positions;
        positions.reserve(keyCount);
        for (std::size_t k = 0; k < keyCount; ++k) positions.push_back(source.positionsAt(local[p][k]));
        const std::vector<std::span<const float>> spans(positions.begin(), positions.end());
        poses_[p]->updateShutter(fractions, spans);
      }
    });
  } catch (...) {
    // A pose left halfway: every pose is refitted again by the next update.
    for (double& t : poseLocalTime_) t = std::numeric_limits<double>::quiet_NaN();
    throw;
  }
  lastRefits_ = uint32_t(stale.size());
  totalRefits_ += stale.size();

  // The instant state at the close (closestHit(ray) without a time, and the still instances).
  std::vector<Aabb> keyBoxes(keyCount * count);
  for (uint32_t i = 0; i < count; ++i) {
    blas_[i] = &runtimeOf(i);
    const std::optional<Affine3x4> space = instanceSpace(sources.instances[i].worldAt(closeTime));
    visible_[i] = space.has_value();
    toInstance_[i] = space.value_or(Affine3x4{});
    const Aabb u = keysUnion(*blas_[i]);
    for (std::size_t k = 0; k < keyCount; ++k) keyBoxes[k * count + i] = instanceKeyBox(u, toWorld[k * count + i]);
  }
  // The TLAS at every key (one topology: a rebuilt one from the open's boxes).
  const auto boxesOf = [&](std::size_t k) { return std::span<const Aabb>(keyBoxes).subspan(k * count, count); };
  if (config_.tlas == TlasUpdate::Rebuild)
    tlas_ = runtimeTopology(flattenBvh(rebuildTlas(boxesOf(0), scene_.objective)), count, kTraversalStackSize,
                            "two-level runtime: TLAS");
  else
    selectTlas(closeTime);  // the part of the instant state at the close
  keyTlasNodes_.resize(keyCount * tlas_.interiorCount);
  keyTlasRootBoxes_.resize(keyCount);
  for (std::size_t k = 0; k < keyCount; ++k) {
    const std::span<const Aabb> boxes = boxesOf(k);
    std::copy(boxes.begin(), boxes.end(), instanceBoxes_.begin());
    refitTlas();
    std::copy_n(tlas_.nodes.begin(), tlas_.interiorCount, keyTlasNodes_.begin() + std::ptrdiff_t(k * tlas_.interiorCount));
    keyTlasRootBoxes_[k] = tlas_.rootBoxes[0];
  }
  keyTimes_ = fractions;
  keySceneTimes_ = keys;
  keyToWorld_ = std::move(toWorld);
  keyInstanceBoxes_ = std::move(keyBoxes);
  moving_ = std::move(moves.movingInstances);
}

std::span<const Aabb> TwoLevelRuntime::keyInstanceBoxes(std::size_t key) const {
  if (key >= keyTimes_.size())
    throw ConfigError("two-level runtime: key " + std::to_string(key) + " of a shutter of " +
                      std::to_string(keyTimes_.size()) + " keys");
  return std::span<const Aabb>(keyInstanceBoxes_).subspan(key * instanceBoxes_.size(), instanceBoxes_.size());
}

detail::TlasKeys TwoLevelRuntime::keysAt(float time) const {
  const motion::Segment seg = motion::segmentAt(keyTimes_.data(), int(keyTimes_.size()), time);
  const std::size_t s = std::size_t(seg.index), count = instanceBoxes_.size();
  detail::TlasKeys keys;
  keys.nodes0 = keyTlasNodes_.data() + s * tlas_.interiorCount;
  keys.nodes1 = keys.nodes0 + tlas_.interiorCount;
  keys.boxes0 = keyInstanceBoxes_.data() + s * count;
  keys.boxes1 = keys.boxes0 + count;
  keys.toWorld0 = keyToWorld_.data() + s * count;
  keys.toWorld1 = keys.toWorld0 + count;
  keys.moving = moving_.data();
  keys.root = motion::lerpBox(keyTlasRootBoxes_[s], keyTlasRootBoxes_[s + 1], seg.f);
  keys.f = seg.f;
  keys.time = time;
  return keys;
}

Affine3x4 TwoLevelRuntime::toWorldAt(uint32_t instance, float time) const {
  if (instance >= scene_.instanceCount())
    throw ConfigError("two-level runtime: instance " + std::to_string(instance) + " of " +
                      std::to_string(scene_.instanceCount()));
  if (!blurred()) return floatRows(scene_.scene.instances[instance].worldAt(time_));
  const detail::TlasKeys keys = keysAt(time);
  return motion::lerpAffine(keys.toWorld0[instance], keys.toWorld1[instance], keys.f);
}

TwoLevelHit TwoLevelRuntime::closestHit(const Ray& ray, float time) const {
  if (!blurred()) return closestHit(ray);
  auto frame = detail::tlasFrame<false, true>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  frame.keys = keysAt(time);
  frame.rootBox = frame.keys.root;
  return detail::twoLevelHit(detail::traverse<false>(frame, ray), frame);
}

bool TwoLevelRuntime::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  if (!blurred()) return anyHit(ray, order);
  auto frame = detail::tlasFrame<true, true>(tlas_, toInstance_, instanceBoxes_, visible_, blas_);
  frame.keys = keysAt(time);
  frame.rootBox = frame.keys.root;
  frame.order = order;
  return detail::traverse<true>(frame, ray).valid();
}

}  // namespace tsah
