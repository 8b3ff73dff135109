#pragma once
// Motion blur: the pieces the CPU runtime, the CUDA kernels, the exporter and the tests share
// (docs/motion-blur.md). A blurred frame keeps one tree topology refitted at the KEY TIMES of its
// shutter; a ray's time tau in [0, 1] (the fraction of the shutter) picks the segment between two
// keys, and the boxes and the triangles' vertices are lerped there with the same formula.
//
// The TSAH_HD functions take plain pointers and counts (no std:: containers) so nvcc compiles them
// for the device; shutterKeys runs on the host only.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/instance_transform.hpp"

namespace tsah::motion {

// The caller's key times, as the runtimes take them: one key anywhere in [0, 1], else first 0, last 1,
// strictly increasing; one per set of positions. Throws tsah::ConfigError starting with `who`
// ("runtime: ", "GPU runtime: updateShutter: ") otherwise. Host only.
void checkKeyTimes(std::span<const float> keyTimes, std::size_t positionSets, const std::string& who);

// The key times of the shutter [open, close]: open, every keyframe time strictly inside, close
// (one key when open == close). Between two consecutive keys every vertex moves linearly, because
// the animation interpolates linearly between its keyframes. keyframeTimes: increasing.
// A keyframe whose shutter fraction (keyFractions) rounds to the previous key's or to 1 in float
// is left out: the runtimes take strictly increasing float fractions, and such a keyframe lies
// within a float rounding of the shutter of that key (e.g. a shutter ending an ulp after it).
inline std::vector<double> shutterKeys(std::span<const double> keyframeTimes, double open,
                                       double close) {
  std::vector<double> keys{open};
  if (close <= open) return keys;
  float previous = 0.0f;
  for (double t : keyframeTimes) {
    if (!(t > open && t < close)) continue;
    const float fraction = static_cast<float>((t - open) / (close - open));  // keyFractions' value
    if (fraction > previous && fraction < 1.0f) {
      keys.push_back(t);
      previous = fraction;
    }
  }
  keys.push_back(close);
  return keys;
}

// The keys as fractions of the shutter (first 0, last 1, increasing), as the runtime keeps them;
// one key gives {0}.
inline std::vector<float> keyFractions(std::span<const double> keys) {
  std::vector<float> fractions(keys.size(), 0.0f);
  if (keys.size() < 2) return fractions;
  const double span = keys.back() - keys.front();
  for (size_t k = 1; k + 1 < keys.size(); ++k)
    fractions[k] = static_cast<float>((keys[k] - keys.front()) / span);
  fractions.back() = 1.0f;
  return fractions;
}

// A ray's place among the keys: segment s (keys s and s + 1) and f in [0, 1] along it.
struct Segment {
  int index = 0;
  float f = 0.0f;
};

// Segment of tau for keys[0..count) (first 0, last 1, increasing): the last key with
// keys[s] <= tau, the last segment for tau >= 1; f = (tau - keys[s]) / (keys[s+1] - keys[s])
// clamped to [0, 1] (so a tau outside [0, 1] or a NaN lands on an end key). One key: {0, 0}.
TSAH_HD Segment segmentAt(const float* keys, int count, float tau) {
  Segment seg;
  if (count < 2) return seg;
  int s = 0;
  while (s + 2 < count && keys[s + 1] <= tau) ++s;  // few keys: a linear scan is cheapest
  float f = (tau - keys[s]) / (keys[s + 1] - keys[s]);
  f = f > 0.0f ? f : 0.0f;  // NaN -> 0
  seg.index = s;
  seg.f = f < 1.0f ? f : 1.0f;
  return seg;
}

// The one lerp formula of motion blur, for boxes and vertices alike: (1 - f) * a + f * b in float
// with round-to-nearest. It gives a at f = 0 and b at f = 1 exactly, so the ends of a segment are
// its keys bit for bit.
// lerpOf and padOf take a float or a SIMD lane vector T (g = 1 - f; the scalars broadcast as T),
// so that the wide kernels run these very operations lane by lane.
template <class T>
TSAH_HD T lerpOf(T a, T b, T f, T g) {
  return g * a + f * b;
}
TSAH_HD float lerp(float a, float b, float f) { return lerpOf(a, b, f, 1.0f - f); }

TSAH_HD Vec3 lerpVertex(Vec3 a, Vec3 b, float f) {
  return {lerp(a.x, b.x, f), lerp(a.y, b.y, f), lerp(a.z, b.z, f)};
}

// An affine map at f between its keys (row-major 3x4 floats), entry by entry with lerp: a blurred
// instance's instance -> world map on the CPU and the GPU.
TSAH_HD Affine3x4 lerpAffine(const Affine3x4& a, const Affine3x4& b, float f) {
  Affine3x4 out;
  for (int i = 0; i < 12; ++i) out.m[i] = lerp(a.m[i], b.m[i], f);
  return out;
}

// The outward pad of a lerped box side on an axis whose four box coordinates (lo and hi at both
// keys) are at most m in magnitude. A computed lerp of values bounded by m errs by at most about
// 4u*m (u = 2^-24: 1 - f, the two products and the sum each add a relative error u; a contracted
// fma only removes some), so the box's and the vertex's lerps together by at most 8u*m; the pad is
// 32u*m = m * 2^-19, of which subtracting it in round-to-nearest keeps at least 30u*m. The absolute
// 2^-120 covers underflow (at most 2^-149 per operation near zero). docs/motion-blur.md derives it.
inline constexpr float kPadPerMagnitude = 0x1p-19f;
inline constexpr float kPadFloor = 0x1p-120f;
template <class T>
TSAH_HD T padOf(T m, T perMagnitude, T floor) {
  return m * perMagnitude + floor;
}
TSAH_HD float lerpPad(float m) { return padOf(m, kPadPerMagnitude, kPadFloor); }

TSAH_HD float maxMagnitude(float a, float b, float c, float d) {
  a = a < 0.0f ? -a : a;
  b = b < 0.0f ? -b : b;
  c = c < 0.0f ? -c : c;
  d = d < 0.0f ? -d : d;
  const float ab = a > b ? a : b, cd = c > d ? c : d;
  return ab > cd ? ab : cd;
}

// The box at f between b0 (key s) and b1 (key s + 1), padded so that it contains lerpVertex(v0, v1,
// f) of every vertex with v0 in b0 and v1 in b1, for every f in [0, 1], under float rounding.
// An empty box (the default) stays empty.
TSAH_HD Aabb lerpBox(const Aabb& b0, const Aabb& b1, float f) {
  Aabb out;
  for (int a = 0; a < 3; ++a) {
    const float pad = lerpPad(maxMagnitude(b0.lo[a], b0.hi[a], b1.lo[a], b1.hi[a]));
    out.lo[a] = lerp(b0.lo[a], b1.lo[a], f) - pad;
    out.hi[a] = lerp(b0.hi[a], b1.hi[a], f) + pad;
  }
  return out;
}

// Pre-padded key boxes (the GPU blurred layout; docs/motion-blur.md#pre-padded-key-boxes): each
// key's box is widened once, when the layout is built, by lerpPad of the largest magnitude its axis
// reaches over all the frame's keys (foldMagnitudes folds one key's box into m), so that a ray's
// lerp of two such boxes needs no pad (blurred_node.hpp moves them). Whatever the segment, that pad
// is at least lerpBox's, and the widening's own rounding (at most u*m) is far inside its margin.
TSAH_HD Vec3 foldMagnitudes(const Aabb& b, Vec3 m) {
  for (int a = 0; a < 3; ++a) m[a] = maxMagnitude(b.lo[a], b.hi[a], m[a], 0.0f);
  return m;
}
TSAH_HD Aabb prepadBox(const Aabb& b, const Vec3& m) {
  Aabb out;
  for (int a = 0; a < 3; ++a) {
    const float pad = lerpPad(m[a]);
    out.lo[a] = b.lo[a] - pad;
    out.hi[a] = b.hi[a] + pad;
  }
  return out;
}

// A box holding lerpBox(c0, c1, f) for every f in [0, 1] and every pair of boxes c0 inside b0 and c1
// inside b1 (a node's children at keys s and s + 1, inside the node's boxes there), under float
// rounding: the two keys' union widened on each side by twice lerpBox's pad of b0 and b1. A child's
// pad is at most that pad (its coordinates are at most as large), and its lerp lies below the
// lower of its two keys by at most about 5u*m (m: the pad's magnitude, u = 2^-24), far less than
// the second pad of 32u*m; docs/motion-blur.md. A ray that misses this box misses every such
// child at every time of the segment.
TSAH_HD Aabb segmentBounds(const Aabb& b0, const Aabb& b1) {
  Aabb out;
  for (int a = 0; a < 3; ++a) {
    const float widen = 2.0f * lerpPad(maxMagnitude(b0.lo[a], b0.hi[a], b1.lo[a], b1.hi[a]));
    out.lo[a] = (b0.lo[a] < b1.lo[a] ? b0.lo[a] : b1.lo[a]) - widen;
    out.hi[a] = (b0.hi[a] > b1.hi[a] ? b0.hi[a] : b1.hi[a]) + widen;
  }
  return out;
}

}  // namespace tsah::motion
