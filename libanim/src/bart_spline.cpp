// Kochanek–Bartels splines of BART's `k` blocks.
//
// Positions and scales: one cubic Hermite segment between each pair of inner keys, with the
// Kochanek–Bartels outgoing and incoming tangents scaled for uneven key spacing. Rotations: the
// quaternion form of the same construction (tangents in the logarithm space, squad between the keys).
// The rotation spline follows the BART reference library's arithmetic on purpose, so scenes move as
// they did for the benchmark's authors: quaternions are built from the axis as written (the reference
// does not normalise it), a key's sign is flipped to keep consecutive keys within 90 degrees only for
// keys 2 .. n-2 and only relative to the key before it, and a flipped key is re-read in later segments
// in its unit-length form. See docs/importers.md.
#include <algorithm>
#include <cmath>
#include <string>

#include "anim/bart.hpp"
#include "tsah/base/error.hpp"

namespace anim::bart {

namespace {

constexpr double kPi = 3.14159265358979323846;
// The reference library's cut-offs for sin(angle) near zero in log, exp and slerp.
constexpr double kSinCutoff = 1e-3;

using Q = Quaternion;

Q operator*(const Q& a, const Q& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y + a.y * b.w + a.z * b.x - a.x * b.z, a.w * b.z + a.z * b.w + a.x * b.y - a.y * b.x};
}
Q operator*(double s, const Q& a) { return {s * a.w, s * a.x, s * a.y, s * a.z}; }
Q operator+(const Q& a, const Q& b) { return {a.w + b.w, a.x + b.x, a.y + b.y, a.z + b.z}; }
Q operator-(const Q& a, const Q& b) { return {a.w - b.w, a.x - b.x, a.y - b.y, a.z - b.z}; }
Q operator-(const Q& a) { return {-a.w, -a.x, -a.y, -a.z}; }
double dot(const Q& a, const Q& b) { return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z; }
Q conjugate(const Q& a) { return {a.w, -a.x, -a.y, -a.z}; }

Q fromAngleAxis(double radians, const std::array<double, 3>& axis) {
  const double s = std::sin(0.5 * radians);
  return {std::cos(0.5 * radians), s * axis[0], s * axis[1], s * axis[2]};
}

// The rotation a (possibly non-unit) quaternion stands for, as a unit quaternion: keeps w (the
// cosine of the half angle) and rescales the vector part, as the reference's round trip through
// angle and axis does.
Q unitize(const Q& a) {
  const double w = std::clamp(a.w, -1.0, 1.0);
  const double len2 = a.x * a.x + a.y * a.y + a.z * a.z;
  if (!(len2 > 0.0)) return {1, 0, 0, 0};
  const double s = std::sqrt(std::max(0.0, 1.0 - w * w) / len2);
  return {w, s * a.x, s * a.y, s * a.z};
}

Q logq(const Q& a) {
  Q r{0, a.x, a.y, a.z};
  if (std::fabs(a.w) < 1.0) {
    const double angle = std::acos(a.w);
    const double sn = std::sin(angle);
    if (std::fabs(sn) >= kSinCutoff) {
      const double c = angle / sn;
      r.x *= c;
      r.y *= c;
      r.z *= c;
    }
  }
  return r;
}

Q expq(const Q& a) {
  const double angle = std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z);
  const double sn = std::sin(angle);
  Q r{std::cos(angle), a.x, a.y, a.z};
  if (std::fabs(sn) >= kSinCutoff) {
    const double c = sn / angle;
    r.x *= c;
    r.y *= c;
    r.z *= c;
  }
  return r;
}

// Slerp without the shortest-arc flip (the spline has already chosen the signs).
Q slerp(double t, const Q& p, const Q& q) {
  const double c = std::clamp(dot(p, q), -1.0, 1.0);
  const double angle = std::acos(c);
  const double sn = std::sin(angle);
  if (sn < kSinCutoff) return p;
  const double c0 = std::sin((1.0 - t) * angle) / sn;
  const double c1 = std::sin(t * angle) / sn;
  return c0 * p + c1 * q;
}

template <typename Key>
void checkKeys(const std::vector<Key>& keys, const char* what) {
  if (keys.size() < 4)
    throw tsah::DataError(std::string(what) +
                          " spline needs at least 4 keys (the first and last only shape the "
                          "end tangents), got " +
                          std::to_string(keys.size()));
  for (std::size_t i = 0; i < keys.size(); ++i)
    if (!std::isfinite(keys[i].time))
      throw tsah::DataError(std::string(what) + " key " + std::to_string(i) + " has a non-finite time");
}

// 2 (t2 - t1) / (tb - ta): the factor that adapts a tangent to uneven key spacing; 1 when the keys
// around it coincide in time (where the reference would divide by zero).
double spacingFactor(double t1, double t2, double ta, double tb) {
  const double span = tb - ta;
  return span != 0.0 ? 2.0 * (t2 - t1) / span : 1.0;
}

// The segment for time t and the parameter u within it, as the reference finds them: clamped before
// the first segment's start and after the last one's end, otherwise the first segment (in key order)
// that ends after t. Key times need not increase (some BART files restart them); u is kept in [0,1].
template <typename Segment>
std::pair<std::size_t, double> locate(const std::vector<Segment>& segments, double t) {
  if (!(segments.front().t0 < t)) return {0, 0.0};
  if (!(t < segments.back().t1)) return {segments.size() - 1, 1.0};
  std::size_t i = 0;
  while (i + 1 < segments.size() && !(t < segments[i].t1)) ++i;
  const double range = segments[i].t1 - segments[i].t0;
  return {i, range != 0.0 ? std::clamp((t - segments[i].t0) / range, 0.0, 1.0) : 0.0};
}

}  // namespace

PositionSpline::PositionSpline(const std::vector<SplineKey>& keys) {
  checkKeys(keys, "position");
  for (std::size_t i0 = 0; i0 + 3 < keys.size(); ++i0) {
    const SplineKey& k0 = keys[i0];
    const SplineKey& k1 = keys[i0 + 1];
    const SplineKey& k2 = keys[i0 + 2];
    const SplineKey& k3 = keys[i0 + 3];
    const double adj0 = spacingFactor(k1.time, k2.time, k0.time, k2.time);
    const double out0 = 0.5 * adj0 * (1 - k1.tension) * (1 + k1.continuity) * (1 + k1.bias);
    const double out1 = 0.5 * adj0 * (1 - k1.tension) * (1 - k1.continuity) * (1 - k1.bias);
    const double adj1 = spacingFactor(k1.time, k2.time, k1.time, k3.time);
    const double in0 = 0.5 * adj1 * (1 - k2.tension) * (1 - k2.continuity) * (1 + k2.bias);
    const double in1 = 0.5 * adj1 * (1 - k2.tension) * (1 + k2.continuity) * (1 - k2.bias);
    Segment s{k1.time, k2.time, {}, {}, {}, {}};
    for (int a = 0; a < 3; ++a) {
      const double d = k2.value[a] - k1.value[a];
      const double tout = out1 * d + out0 * (k1.value[a] - k0.value[a]);
      const double tin = in1 * (k3.value[a] - k2.value[a]) + in0 * d;
      s.c0[a] = k1.value[a];
      s.c1[a] = tout;
      s.c2[a] = 3 * d - 2 * tout - tin;
      s.c3[a] = -2 * d + tout + tin;
    }
    segments_.push_back(s);
  }
}

std::array<double, 3> PositionSpline::at(double t) const {
  if (segments_.empty()) return {0, 0, 0};
  const auto [i, u] = locate(segments_, t);
  const Segment& s = segments_[i];
  std::array<double, 3> v;
  for (int a = 0; a < 3; ++a) v[a] = s.c0[a] + u * (s.c1[a] + u * (s.c2[a] + u * s.c3[a]));
  return v;
}

double PositionSpline::startTime() const { return segments_.empty() ? 0.0 : segments_.front().t0; }
double PositionSpline::endTime() const { return segments_.empty() ? 0.0 : segments_.back().t1; }

RotationSpline::RotationSpline(const std::vector<RotationKey>& keys) {
  checkKeys(keys, "rotation");
  const std::size_t n = keys.size();
  std::vector<Q> raw(n);
  for (std::size_t i = 0; i < n; ++i) raw[i] = fromAngleAxis(keys[i].angleDegrees * kPi / 180.0, keys[i].axis);
  // flipped[j]: key j was negated to lie within 90 degrees of key j-1 (decided in segment j-2).
  std::vector<bool> flipped(n, false);
  // A key as an earlier segment left it: once flipped it is stored as angle and axis, so later
  // segments see the unit-length negation.
  auto stored = [&](std::size_t j) { return flipped[j] ? unitize(-raw[j]) : raw[j]; };
  for (std::size_t i0 = 0; i0 + 3 < n; ++i0) {
    const std::size_t i1 = i0 + 1, i2 = i0 + 2, i3 = i0 + 3;
    const Q q0 = stored(i0);
    const Q q1 = stored(i1);
    Q q2 = raw[i2];
    if (dot(q1, q2) < 0.0) {
      flipped[i2] = true;
      q2 = -q2;
    }
    const Q q3 = raw[i3];  // not yet sign-adjusted: that happens in the next segment

    const RotationKey& k1 = keys[i1];
    const RotationKey& k2 = keys[i2];
    const Q logdq = logq(conjugate(q1) * q2);
    const double adj0 = spacingFactor(k1.time, k2.time, keys[i0].time, k2.time);
    const double out0 = 0.5 * adj0 * (1 - k1.tension) * (1 + k1.continuity) * (1 + k1.bias);
    const double out1 = 0.5 * adj0 * (1 - k1.tension) * (1 - k1.continuity) * (1 - k1.bias);
    const Q tout = out1 * logdq + out0 * logq(conjugate(q0) * q1);
    const double adj1 = spacingFactor(k1.time, k2.time, k1.time, keys[i3].time);
    const double in0 = 0.5 * adj1 * (1 - k2.tension) * (1 - k2.continuity) * (1 + k2.bias);
    const double in1 = 0.5 * adj1 * (1 - k2.tension) * (1 + k2.continuity) * (1 - k2.bias);
    const Q tin = in0 * logdq + in1 * logq(conjugate(q2) * q3);

    Segment s;
    s.t0 = k1.time;
    s.t1 = k2.time;
    s.p = q1;
    s.q = q2;
    s.a = q1 * expq(0.5 * (tout - logdq));
    s.b = q2 * expq(0.5 * (logdq - tin));
    segments_.push_back(s);
  }
}

Quaternion RotationSpline::at(double t) const {
  if (segments_.empty()) return {};
  const auto [i, u] = locate(segments_, t);
  const Segment& s = segments_[i];
  const Q squad = slerp(2 * u * (1 - u), slerp(u, s.p, s.q), slerp(u, s.a, s.b));
  return unitize(squad);
}

double RotationSpline::startTime() const { return segments_.empty() ? 0.0 : segments_.front().t0; }
double RotationSpline::endTime() const { return segments_.empty() ? 0.0 : segments_.back().t1; }

std::array<double, 9> rotationMatrix(const Quaternion& q) {
  const double x2 = q.x + q.x, y2 = q.y + q.y, z2 = q.z + q.z;
  const double xx = q.x * x2, xy = q.x * y2, xz = q.x * z2;
  const double yy = q.y * y2, yz = q.y * z2, zz = q.z * z2;
  const double wx = q.w * x2, wy = q.w * y2, wz = q.w * z2;
  return {1.0 - (yy + zz), xy - wz,         xz + wy,  //
          xy + wz,         1.0 - (xx + zz), yz - wx,  //
          xz - wy,         yz + wx,         1.0 - (xx + yy)};
}

}  // namespace anim::bart
