#include "anim/animation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "anim/binary_io.hpp"
#include "anim/error.hpp"

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

std::size_t firstBadCoordinate(std::span<const float> positions) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!(std::fabs(positions[i]) <= kMaxCoordinate)) return i;  // NaN fails the comparison too
  return positions.size();
}

std::string describeBadCoordinate(float value) {
  if (!std::isfinite(value)) return "has a NaN or infinite coordinate";
  char text[128];
  std::snprintf(text, sizeof text, "has coordinate %g, beyond the supported magnitude %g", double(value),
                double(kMaxCoordinate));
  return std::string(text) + " (surface areas would overflow)";
}

Animation::Animation(std::vector<uint32_t> indices, uint32_t vertexCount,
                     std::vector<float> positions, std::vector<double> times, std::string name)
    : name_(std::move(name)),
      indices_(std::move(indices)),
      vertexCount_(vertexCount),
      positions_(std::move(positions)),
      times_(std::move(times)) {
  const std::string who = name_.empty() ? std::string("animation") : name_;
  if (indices_.size() % 3 != 0)
    throw ImportError(who, "index count " + std::to_string(indices_.size()) + " is not a multiple of 3");
  if (times_.empty()) throw ImportError(who, "no keyframes");
  if (positions_.size() != times_.size() * std::size_t(vertexCount_) * 3)
    throw ImportError(who, "position array holds " + std::to_string(positions_.size()) +
                               " floats, expected " + std::to_string(times_.size()) + " keyframes x " +
                               std::to_string(vertexCount_) + " vertices x 3");
  for (std::size_t i = 0; i < indices_.size(); ++i)
    if (indices_[i] >= vertexCount_)
      throw ImportError(who, "triangle " + std::to_string(i / 3) + " references vertex " +
                                 std::to_string(indices_[i]) + " but there are only " +
                                 std::to_string(vertexCount_) + " vertices");
  for (std::size_t i = 0; i < times_.size(); ++i) {
    if (!std::isfinite(times_[i]))
      throw ImportError(who, "keyframe " + std::to_string(i) + " has a non-finite time");
    if (i > 0 && !(times_[i] > times_[i - 1]))
      throw ImportError(who, "keyframe times are not strictly increasing at keyframe " + std::to_string(i));
  }
  if (const std::size_t bad = firstBadCoordinate(positions_); bad < positions_.size()) {
    const std::size_t perFrame = std::size_t(vertexCount_) * 3;
    throw ImportError(who, "keyframe " + std::to_string(bad / perFrame) + " vertex " +
                               std::to_string((bad % perFrame) / 3) + " " + describeBadCoordinate(positions_[bad]));
  }
  const float* p = positions_.data();
  for (std::size_t t = 0; t < indices_.size(); t += 3)
    if (triangleIsDegenerate(p + 3 * indices_[t], p + 3 * indices_[t + 1], p + 3 * indices_[t + 2]))
      ++degenerate_;
}

std::span<const float> Animation::keyframe(uint32_t k) const {
  const std::size_t n = std::size_t(vertexCount_) * 3;
  return std::span<const float>(positions_).subspan(std::size_t(k) * n, n);
}

KeyframeBlend keyframeBlend(std::span<const double> times, double t) {
  if (times.size() <= 1 || t <= times.front()) return {0, 0.0f};
  if (t >= times.back()) return {static_cast<uint32_t>(times.size() - 1), 0.0f};
  const auto it = std::upper_bound(times.begin(), times.end(), t);  // first time > t
  const auto k = static_cast<uint32_t>(it - times.begin()) - 1;
  return {k, static_cast<float>((t - times[k]) / (times[k + 1] - times[k]))};
}

void Animation::positionsAt(double t, std::span<float> out) const {
  const auto [k, alpha] = keyframeBlend(times_, t);
  const auto a = keyframe(k);
  if (alpha == 0.0f) {
    std::copy(a.begin(), a.end(), out.begin());
    return;
  }
  const auto b = keyframe(k + 1);
  const float beta = 1.0f - alpha;
  for (std::size_t i = 0; i < a.size(); ++i) out[i] = beta * a[i] + alpha * b[i];
}

std::vector<float> Animation::positionsAt(double t) const {
  std::vector<float> out(std::size_t(vertexCount_) * 3);
  positionsAt(t, out);
  return out;
}

Bounds Animation::keyframeBounds(uint32_t k) const {
  Bounds b;
  const auto p = keyframe(k);
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
  Bounds b;
  for (uint32_t k = 0; k < keyframeCount(); ++k) b.extend(keyframeBounds(k));
  return b;
}

std::vector<double> Animation::uniformTimes(uint32_t n) const {
  std::vector<double> t(n);
  const double t0 = startTime(), t1 = endTime();
  for (uint32_t i = 0; i < n; ++i) t[i] = n == 1 ? t0 : t0 + (t1 - t0) * double(i) / double(n - 1);
  if (n > 1) t.back() = t1;  // exact end despite rounding
  return t;
}

Animation Animation::resample(uint32_t n) const {
  if (n == 0) throw Error(name_ + ": cannot resample to 0 frames");
  requireMemory(uint64_t(n) * (uint64_t(vertexCount_) * 3 * sizeof(float) + sizeof(double)), name_,
                "resampling to " + std::to_string(n) + " frames of " + std::to_string(vertexCount_) + " vertices");
  std::vector<double> t = uniformTimes(n);
  if (n > 1 && !(endTime() > startTime())) {
    // A one-keyframe animation sampled n times: frames at 0,1,...; the geometry stays the same.
    for (uint32_t i = 0; i < n; ++i) t[i] = startTime() + i;
  }
  const std::size_t perFrame = std::size_t(vertexCount_) * 3;
  std::vector<float> pos(perFrame * n);
  for (uint32_t i = 0; i < n; ++i)
    positionsAt(t[i], std::span<float>(pos).subspan(i * perFrame, perFrame));
  Animation result(indices_, vertexCount_, std::move(pos), std::move(t), name_);
  result.camera_ = camera_;
  return result;
}

Animation Animation::segment(double t0, double t1) const {
  t0 = std::clamp(t0, startTime(), endTime());
  t1 = std::clamp(t1, startTime(), endTime());
  if (!(t1 > t0)) t1 = t0;
  std::vector<double> t{t0};
  for (double k : times_)
    if (k > t0 && k < t1) t.push_back(k);
  if (t1 > t0) t.push_back(t1);
  const std::size_t perFrame = std::size_t(vertexCount_) * 3;
  std::vector<float> pos(perFrame * t.size());
  for (std::size_t i = 0; i < t.size(); ++i)
    positionsAt(t[i], std::span<float>(pos).subspan(i * perFrame, perFrame));
  Animation result(indices_, vertexCount_, std::move(pos), std::move(t), name_);
  result.camera_ = camera_;
  return result;
}

std::size_t Animation::memoryBytes() const {
  return indices_.size() * sizeof(uint32_t) + positions_.size() * sizeof(float) +
         times_.size() * sizeof(double);
}

}  // namespace anim
