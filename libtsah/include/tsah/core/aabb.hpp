#pragma once
// Vec3 and axis-aligned boxes shared by the CPU code and the CUDA kernels.
#include <cstdint>
#include <type_traits>

#include "tsah/core/hd.hpp"

namespace tsah {

struct Vec3 {
  float x, y, z;

  TSAH_HD float operator[](int a) const { return a == 0 ? x : (a == 1 ? y : z); }
  TSAH_HD float& operator[](int a) { return a == 0 ? x : (a == 1 ? y : z); }
};

TSAH_HD Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
TSAH_HD Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
TSAH_HD Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
TSAH_HD Vec3 operator*(float s, Vec3 a) { return {a.x * s, a.y * s, a.z * s}; }
TSAH_HD float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
TSAH_HD Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
TSAH_HD Vec3 vmin(Vec3 a, Vec3 b) {
  return {a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z};
}
TSAH_HD Vec3 vmax(Vec3 a, Vec3 b) {
  return {a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z};
}

// An empty box has lo > hi (the default), so extending it by anything gives that thing.
struct Aabb {
  Vec3 lo{3.402823466e38f, 3.402823466e38f, 3.402823466e38f};
  Vec3 hi{-3.402823466e38f, -3.402823466e38f, -3.402823466e38f};

  TSAH_HD bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  TSAH_HD void extend(Vec3 p) {
    lo = vmin(lo, p);
    hi = vmax(hi, p);
  }
  TSAH_HD void extend(const Aabb& b) {
    lo = vmin(lo, b.lo);
    hi = vmax(hi, b.hi);
  }
  TSAH_HD Vec3 center() const { return (lo + hi) * 0.5f; }
  TSAH_HD Vec3 extent() const { return hi - lo; }
  // Surface area; 0 for an empty box.
  TSAH_HD float area() const {
    if (empty()) return 0.0f;
    const Vec3 d = hi - lo;
    return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
  TSAH_HD bool contains(const Aabb& b) const {
    return b.lo.x >= lo.x && b.lo.y >= lo.y && b.lo.z >= lo.z && b.hi.x <= hi.x &&
           b.hi.y <= hi.y && b.hi.z <= hi.z;
  }
  TSAH_HD int largestAxis() const {
    const Vec3 d = extent();
    return d.x >= d.y && d.x >= d.z ? 0 : (d.y >= d.z ? 1 : 2);
  }
};

TSAH_HD Aabb merge(Aabb a, const Aabb& b) {
  a.extend(b);
  return a;
}

static_assert(sizeof(Vec3) == 12 && alignof(Vec3) == 4);
static_assert(sizeof(Aabb) == 24 && alignof(Aabb) == 4);
static_assert(std::is_trivially_copyable_v<Aabb>);

}  // namespace tsah
