#pragma once
// BART scenes (Lext, Assarsson, Möller: "A Benchmark for Animated Ray Tracing", 2001) in AFF, the
// animated extension of NFF, baked into an anim::Animation.
//
// Geometry: `m` indexed meshes, `p`/`pp` polygons (fanned into triangles), `tt`/`ttp` textured
// triangles, `tpa` animated triangles (key shapes interpolated linearly in time), `c` cones and
// cylinders and `s` spheres (tessellated). Transforms: `xs` static (T*R*S) and `x` animated, driven by
// the `k` block of the same name (Kochanek–Bartels splines for translation, rotation and scale, the
// rotation interpolated as the BART reference code does; optional visibility keys). `i` includes
// resolve against the including file's folder, `d` sets the detail level. The `a t0 t1 frames` line
// gives the sampling; every frame becomes one keyframe. The `v` view and a `k camera` block become the
// animation's camera path. Materials, lights, textures and the background are skipped with one
// summary warning. Format and interpolation notes: docs/importers.md.
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "anim/animation.hpp"

namespace anim {

struct BartOptions {
  // 0: the frames of the scene's `a t0 t1 frames` line; otherwise frames every 1/fps from t0 to t1.
  double fps = 0.0;
  // Segments around a tessellated cone, cylinder or sphere (at least 3).
  uint32_t tessellation = 16;
  // Deepest include nesting accepted; include cycles are an error at any depth.
  uint32_t maxIncludeDepth = 32;
  // Scenes whose keyframe positions would need more memory than this are refused before allocating.
  uint64_t maxPositionBytes = uint64_t(8) << 30;
  // Non-fatal findings (skipped materials and lights, transforms without keys, ...). May be empty.
  std::function<void(const std::string&)> warning;
  // Frames sampled so far (done, total); called from worker threads, one call at a time. May be empty.
  std::function<void(std::size_t done, std::size_t total)> progress;
};

// Loads the AFF scene at `path` with everything it includes. Throws tsah::FileError whose message
// names the file and line of the problem.
Animation importBart(const std::string& path, const BartOptions& options = {});

// Parses AFF text held in memory as if it were the file `path` (includes resolve against its folder).
Animation importBartText(std::string_view text, const std::string& path, const BartOptions& options = {});

namespace bart {

// One key of a Kochanek–Bartels spline: a value (translation or scale) with its tension, continuity
// and bias.
struct SplineKey {
  double time = 0.0;
  std::array<double, 3> value{0, 0, 0};
  double tension = 0.0, continuity = 0.0, bias = 0.0;
};

// Piecewise cubic Hermite curve through keys[1] .. keys[n-2]; the first and the last key only shape
// the end tangents (BART needs at least 4 keys). Outside [keys[1].time, keys[n-2].time] the value is
// clamped to the end key. Key times should increase; where a file restarts them, time t uses the first
// segment in key order that ends after t (the reference's lookup).
class PositionSpline {
 public:
  PositionSpline() = default;
  // Throws tsah::DataError for fewer than 4 keys or a non-finite time.
  explicit PositionSpline(const std::vector<SplineKey>& keys);
  std::array<double, 3> at(double t) const;
  double startTime() const;
  double endTime() const;

 private:
  struct Segment {
    double t0, t1;
    std::array<double, 3> c0, c1, c2, c3;  // value(u) = c0 + u c1 + u^2 c2 + u^3 c3, u in [0,1]
  };
  std::vector<Segment> segments_;
};

struct Quaternion {
  double w = 1.0, x = 0.0, y = 0.0, z = 0.0;
};

struct RotationKey {
  double time = 0.0;
  std::array<double, 3> axis{1, 0, 0};
  double angleDegrees = 0.0;
  double tension = 0.0, continuity = 0.0, bias = 0.0;
};

// Kochanek–Bartels rotation spline: squad between the quaternions of keys[1] .. keys[n-2] with
// tangents from the neighbouring keys, as the BART reference library builds it (including its
// choice of quaternion signs and its use of the axis as written). Clamped like PositionSpline.
class RotationSpline {
 public:
  RotationSpline() = default;
  // Throws tsah::DataError for fewer than 4 keys or a non-finite time.
  explicit RotationSpline(const std::vector<RotationKey>& keys);
  // The unit quaternion at time t.
  Quaternion at(double t) const;
  double startTime() const;
  double endTime() const;

 private:
  struct Segment {
    double t0, t1;
    Quaternion p, a, b, q;  // squad(u) = slerp(slerp(p,q,u), slerp(a,b,u), 2u(1-u))
  };
  std::vector<Segment> segments_;
};

// Row-major 3x3 rotation matrix of a unit quaternion.
std::array<double, 9> rotationMatrix(const Quaternion& q);

}  // namespace bart
}  // namespace anim
