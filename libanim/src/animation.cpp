#include "anim/animation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <string>

#include <cstring>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"

namespace anim {

namespace {

bool triangleIsDegenerate(const float* a, const float* b, const float* c) {
  const double e1[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const double e2[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
  return n[0] == 0.0 && n[1] == 0.0 && n[2] == 0.0;
}

}  // namespace

Animation::Animation(std::vector<uint32_t> indices, uint32_t vertexCount,
                     std::vector<float> positions, std::vector<double> times, std::string name)
    : name_(std::move(name)),
      indices_(std::move(indices)),
      vertexCount_(vertexCount),
      movingCount_(vertexCount),
      motion_(std::move(positions)),
      times_(std::move(times)) {
  validate();
  compactStaticVertices();
}

Animation Animation::withStaticVertices(std::vector<uint32_t> indices, std::vector<float> rest,
                                        std::vector<uint32_t> moving, std::vector<float> motion,
                                        std::vector<double> times, std::string name) {
  Animation a;
  a.name_ = std::move(name);
  const std::string who = a.name_.empty() ? std::string("animation") : a.name_;
  if (rest.size() % 3 != 0 || rest.size() / 3 > 0xffffffffu)
    throw tsah::FileError(who, "rest position array holds " + std::to_string(rest.size()) + " floats, not 3 per vertex");
  a.vertexCount_ = static_cast<uint32_t>(rest.size() / 3);
  for (std::size_t i = 0; i < moving.size(); ++i)
    if (moving[i] >= a.vertexCount_ || (i > 0 && moving[i] <= moving[i - 1]))
      throw tsah::FileError(who, "moving vertex ids are not ascending ids below the vertex count");
  a.movingCount_ = static_cast<uint32_t>(moving.size());
  a.indices_ = std::move(indices);
  a.motion_ = std::move(motion);
  a.times_ = std::move(times);
  if (a.movingCount_ < a.vertexCount_) {
    a.rest_ = std::move(rest);
    a.moving_ = std::move(moving);
  }
  a.validate();
  if (!a.allMoving())
    for (uint32_t m = 0; m < a.movingCount_; ++m)
      std::copy_n(a.motion_.data() + 3 * std::size_t(m), 3, a.rest_.data() + 3 * std::size_t(a.moving_[m]));
  return a;
}

double Animation::largestExtent() const {
  // Over the rest positions and every keyframe of the moving vertices: at least the true extent.
  double low[3] = {INFINITY, INFINITY, INFINITY}, high[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const std::vector<float>* block : {&rest_, &motion_})
    for (std::size_t i = 0; i < block->size(); ++i) {
      low[i % 3] = std::min(low[i % 3], double((*block)[i]));
      high[i % 3] = std::max(high[i % 3], double((*block)[i]));
    }
  double extent = 0.0;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, high[a] - low[a]);
  return extent;
}

void Animation::validate() {
  const std::string who = name_.empty() ? std::string("animation") : name_;
  if (indices_.size() % 3 != 0)
    throw tsah::FileError(who, "index count " + std::to_string(indices_.size()) + " is not a multiple of 3");
  if (times_.empty()) throw tsah::FileError(who, "no keyframes");
  if (motion_.size() != times_.size() * std::size_t(movingCount_) * 3)
    throw tsah::FileError(who, "position array holds " + std::to_string(motion_.size()) +
                               " floats, expected " + std::to_string(times_.size()) + " keyframes x " +
                               std::to_string(movingCount_) + " vertices x 3");
  for (std::size_t i = 0; i < indices_.size(); ++i)
    if (indices_[i] >= vertexCount_)
      throw tsah::FileError(who, "triangle " + std::to_string(i / 3) + " references vertex " +
                                 std::to_string(indices_[i]) + " but there are only " +
                                 std::to_string(vertexCount_) + " vertices");
  for (std::size_t i = 0; i < times_.size(); ++i) {
    if (!std::isfinite(times_[i]))
      throw tsah::FileError(who, "keyframe " + std::to_string(i) + " has a non-finite time");
    if (i > 0 && !(times_[i] > times_[i - 1]))
      throw tsah::FileError(who, "keyframe times are not strictly increasing at keyframe " + std::to_string(i));
  }
  if (const std::size_t bad = firstBadCoordinate(rest_); bad < rest_.size())
    throw tsah::FileError(who, "static vertex " + std::to_string(bad / 3) + " " + describeBadCoordinate(rest_[bad]));
  if (const std::size_t bad = firstBadCoordinate(motion_); bad < motion_.size()) {
    const std::size_t perFrame = std::size_t(movingCount_) * 3;
    const std::size_t m = (bad % perFrame) / 3;
    throw tsah::FileError(who, "keyframe " + std::to_string(bad / perFrame) + " vertex " +
                               std::to_string(allMoving() ? m : moving_[m]) + " " + describeBadCoordinate(motion_[bad]));
  }
  if (const double extent = largestExtent(); extent > 0.0 && extent < double(kMinExtent)) {
    char text[160];
    std::snprintf(text, sizeof text, "the model spans only %g (the largest side of its bounding box), below the "
                  "supported %g (surface areas would underflow to zero); scale it up", extent, double(kMinExtent));
    throw tsah::FileError(who, text);
  }
  degenerate_ = 0;
  const float* p0 = allMoving() ? motion_.data() : rest_.data();  // keyframe 0 of every vertex
  for (std::size_t t = 0; t < indices_.size(); t += 3)
    if (triangleIsDegenerate(p0 + 3 * indices_[t], p0 + 3 * indices_[t + 1], p0 + 3 * indices_[t + 2]))
      ++degenerate_;
}

void Animation::compactStaticVertices() {
  const std::size_t frames = times_.size();
  if (frames < 2 || !allMoving()) return;
  const std::size_t perFrame = std::size_t(vertexCount_) * 3;
  std::vector<uint32_t> moving;
  for (uint32_t v = 0; v < vertexCount_; ++v) {
    const float* p = motion_.data() + 3 * std::size_t(v);
    for (std::size_t k = 1; k < frames; ++k)
      if (std::memcmp(p, p + k * perFrame, 3 * sizeof(float)) != 0) {
        moving.push_back(v);
        break;
      }
  }
  const std::size_t split = memoryBytesFor(triangleCount(), vertexCount_, moving.size(), frames);
  if (split >= memoryBytesFor(triangleCount(), vertexCount_, vertexCount_, frames)) return;
  std::vector<float> motion(frames * moving.size() * 3);
  for (std::size_t k = 0; k < frames; ++k)
    for (std::size_t m = 0; m < moving.size(); ++m)
      std::copy_n(motion_.data() + k * perFrame + 3 * std::size_t(moving[m]), 3, motion.data() + (k * moving.size() + m) * 3);
  rest_.assign(motion_.begin(), motion_.begin() + std::ptrdiff_t(perFrame));
  movingCount_ = static_cast<uint32_t>(moving.size());
  moving_ = std::move(moving);
  motion_ = std::move(motion);
}

std::span<const float> Animation::movingKeyframe(uint32_t k) const {
  const std::size_t n = std::size_t(movingCount_) * 3;
  return std::span<const float>(motion_).subspan(std::size_t(k) * n, n);
}

std::vector<float> Animation::keyframe(uint32_t k) const {
  if (k >= keyframeCount()) throw tsah::ConfigError(name_ + ": keyframe " + std::to_string(k) + " out of range");
  std::vector<float> out = allMoving() ? std::vector<float>() : rest_;
  out.resize(std::size_t(vertexCount_) * 3);
  movingPositionsAt(times_[k], out);
  return out;
}

std::vector<float> Animation::allPositions() const {
  const std::size_t perFrame = std::size_t(vertexCount_) * 3;
  std::vector<float> out(perFrame * keyframeCount());
  for (uint32_t k = 0; k < keyframeCount(); ++k)
    positionsAt(times_[k], std::span<float>(out).subspan(k * perFrame, perFrame));
  return out;
}

KeyframeBlend keyframeBlend(std::span<const double> times, double t) {
  if (times.size() <= 1 || t <= times.front()) return {0, 0.0f};
  if (t >= times.back()) return {static_cast<uint32_t>(times.size() - 1), 0.0f};
  const auto it = std::upper_bound(times.begin(), times.end(), t);  // first time > t
  const auto k = static_cast<uint32_t>(it - times.begin()) - 1;
  return {k, static_cast<float>((t - times[k]) / (times[k + 1] - times[k]))};
}

void Animation::interpolateMoving(double t, float* out, const uint32_t* scatter) const {
  const auto [k, alpha] = keyframeBlend(times_, t);
  const float* a = movingKeyframe(k).data();
  const std::size_t n = std::size_t(movingCount_) * 3;
  if (!scatter) {
    if (alpha == 0.0f) {  // copies keyframe k (1 * x + 0 * y would turn -0 into +0)
      std::copy_n(a, n, out);
      return;
    }
    const float* b = movingKeyframe(k + 1).data();
    const float beta = 1.0f - alpha;
    for (std::size_t i = 0; i < n; ++i) out[i] = beta * a[i] + alpha * b[i];
    return;
  }
  if (alpha == 0.0f) {
    for (std::size_t m = 0; m < movingCount_; ++m) std::copy_n(a + 3 * m, 3, out + 3 * std::size_t(scatter[m]));
    return;
  }
  const float* b = movingKeyframe(k + 1).data();
  const float beta = 1.0f - alpha;
  for (std::size_t m = 0; m < movingCount_; ++m) {
    float* dst = out + 3 * std::size_t(scatter[m]);
    for (std::size_t c = 0; c < 3; ++c) dst[c] = beta * a[3 * m + c] + alpha * b[3 * m + c];
  }
}

void Animation::movingPositionsAt(double t, std::span<float> out) const {
  if (out.size() != std::size_t(vertexCount_) * 3)
    throw tsah::ConfigError(name_ + ": position buffer holds " + std::to_string(out.size()) + " floats, expected " +
                            std::to_string(std::size_t(vertexCount_) * 3));
  interpolateMoving(t, out.data(), allMoving() ? nullptr : moving_.data());
}

void Animation::positionsAt(double t, std::span<float> out) const {
  if (!allMoving() && out.size() == rest_.size()) std::copy(rest_.begin(), rest_.end(), out.begin());
  movingPositionsAt(t, out);
}

std::vector<float> Animation::positionsAt(double t) const {
  std::vector<float> out(std::size_t(vertexCount_) * 3);
  positionsAt(t, out);
  return out;
}

Bounds Animation::staticBounds() const {
  Bounds b;
  std::size_t m = 0;
  for (uint32_t v = 0; v < vertexCount_ && !allMoving(); ++v) {
    if (m < moving_.size() && moving_[m] == v) {
      ++m;
      continue;
    }
    b.extend(rest_.data() + 3 * std::size_t(v));
  }
  return b;
}

Bounds Animation::keyframeBounds(uint32_t k) const {
  Bounds b = staticBounds();
  const auto p = movingKeyframe(k);
  for (std::size_t i = 0; i < p.size(); i += 3) b.extend(p.data() + i);
  return b;
}

Bounds Animation::boundsAt(double t) const {
  Bounds b;
  const auto p = positionsAt(t);
  for (std::size_t i = 0; i < p.size(); i += 3) b.extend(p.data() + i);
  return b;
}

Bounds Animation::bounds() const {
  Bounds b = staticBounds();
  for (std::size_t i = 0; i < motion_.size(); i += 3) b.extend(motion_.data() + i);
  return b;
}

std::vector<double> Animation::uniformTimes(uint32_t n) const {
  std::vector<double> t(n);
  const double t0 = startTime(), t1 = endTime();
  for (uint32_t i = 0; i < n; ++i) t[i] = n == 1 ? t0 : t0 + (t1 - t0) * double(i) / double(n - 1);
  if (n > 1) t.back() = t1;  // exact end despite rounding
  return t;
}

Animation Animation::sampledAt(std::vector<double> t) const {
  const std::size_t perFrame = std::size_t(movingCount_) * 3;
  std::vector<float> motion(perFrame * t.size());
  for (std::size_t i = 0; i < t.size(); ++i) interpolateMoving(t[i], motion.data() + i * perFrame, nullptr);
  Animation result;
  result.name_ = name_;
  result.indices_ = indices_;
  result.vertexCount_ = vertexCount_;
  result.movingCount_ = movingCount_;
  result.rest_ = rest_;
  result.moving_ = moving_;
  result.motion_ = std::move(motion);
  result.times_ = std::move(t);
  result.degenerate_ = degenerate_;
  result.camera_ = camera_;
  return result;
}

Animation Animation::resample(uint32_t n) const {
  if (n == 0) throw tsah::ConfigError(name_ + ": cannot resample to 0 frames");
  tsah::checkFitsInMemory(memoryBytesFor(triangleCount(), vertexCount_, movingCount_, n), name_, std::to_string(n) + " frames");
  std::vector<double> t = uniformTimes(n);
  if (n > 1 && !(endTime() > startTime())) {
    // A one-keyframe animation sampled n times: frames at 0,1,...; the geometry stays the same.
    for (uint32_t i = 0; i < n; ++i) t[i] = startTime() + i;
  }
  return sampledAt(std::move(t));
}

Animation Animation::segment(double t0, double t1) const {
  t0 = std::clamp(t0, startTime(), endTime());
  t1 = std::clamp(t1, startTime(), endTime());
  if (!(t1 > t0)) t1 = t0;
  std::vector<double> t{t0};
  for (double k : times_)
    if (k > t0 && k < t1) t.push_back(k);
  if (t1 > t0) t.push_back(t1);
  return sampledAt(std::move(t));
}

std::size_t Animation::memoryBytesFor(uint64_t triangles, uint64_t vertices, uint64_t movingVertices,
                                      uint64_t keyframes) {
  // In 128 bits, saturated: hostile counts (a scene's instances x keyframes) must not wrap to a small size.
  __extension__ typedef unsigned __int128 Wide;
  const Wide split = movingVertices < vertices ? Wide(vertices) * 12 + Wide(movingVertices) * 4 : 0;
  const Wide bytes = Wide(triangles) * 12 + split + Wide(keyframes) * movingVertices * 12 + Wide(keyframes) * 8;
  return bytes > std::numeric_limits<std::size_t>::max() ? std::numeric_limits<std::size_t>::max() : std::size_t(bytes);
}

std::size_t Animation::memoryBytes() const {
  return indices_.size() * sizeof(uint32_t) + rest_.size() * sizeof(float) + moving_.size() * sizeof(uint32_t) +
         motion_.size() * sizeof(float) + times_.size() * sizeof(double);
}

}  // namespace anim
