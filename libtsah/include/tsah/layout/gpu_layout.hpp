#pragma once
// The GPU-ready binary BVH node (Aila & Laine 2009 layout), shared by the .tbvh file, the exported
// renderer buffers, the CPU runtime and the CUDA runtime. Plain data, one definition everywhere.
//
// Each interior node stores the boxes of its two children and two child references, so one
// 64-byte load (four 16-byte vectors) gives everything a traversal step needs:
//   n0xy = (c0.lo.x, c0.hi.x, c0.lo.y, c0.hi.y)
//   n1xy = (c1.lo.x, c1.hi.x, c1.lo.y, c1.hi.y)
//   nz   = (c0.lo.z, c0.hi.z, c1.lo.z, c1.hi.z)
//   refs = (ref0, ref1, count0, count1)
// A child reference ref >= 0 is the index of an interior node (count must be 0); ref < 0 is a
// leaf holding triangle slots [~ref, ~ref + count) of the triangle index array (count >= 1).
// Node 0 is the root when the tree has interior nodes; docs/tbvh-format.md is the full spec.
#include <cstdint>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"

namespace tsah {

struct alignas(16) GpuBvhNode {
  float c0loX, c0hiX, c0loY, c0hiY;  // n0xy
  float c1loX, c1hiX, c1loY, c1hiY;  // n1xy
  float c0loZ, c0hiZ, c1loZ, c1hiZ;  // nz
  int32_t ref0, ref1;                // child references (see above)
  uint32_t count0, count1;           // leaf triangle counts, 0 for interior children

  TSAH_HD Aabb childBox(int c) const {
    Aabb b;
    if (c == 0) {
      b.lo = {c0loX, c0loY, c0loZ};
      b.hi = {c0hiX, c0hiY, c0hiZ};
    } else {
      b.lo = {c1loX, c1loY, c1loZ};
      b.hi = {c1hiX, c1hiY, c1hiZ};
    }
    return b;
  }
  TSAH_HD void setChildBox(int c, const Aabb& b) {
    if (c == 0) {
      c0loX = b.lo.x, c0hiX = b.hi.x, c0loY = b.lo.y, c0hiY = b.hi.y, c0loZ = b.lo.z, c0hiZ = b.hi.z;
    } else {
      c1loX = b.lo.x, c1hiX = b.hi.x, c1loY = b.lo.y, c1hiY = b.hi.y, c1loZ = b.lo.z, c1hiZ = b.hi.z;
    }
  }
  TSAH_HD int32_t childRef(int c) const { return c == 0 ? ref0 : ref1; }
  TSAH_HD uint32_t childCount(int c) const { return c == 0 ? count0 : count1; }
  TSAH_HD Aabb bounds() const { return merge(childBox(0), childBox(1)); }
};

static_assert(sizeof(GpuBvhNode) == 64 && alignof(GpuBvhNode) == 16);
static_assert(std::is_trivially_copyable_v<GpuBvhNode> && std::is_standard_layout_v<GpuBvhNode>);

// Child reference helpers (the same encoding as Aila–Laine's "~leaf" convention).
TSAH_HD bool isLeafRef(int32_t ref) { return ref < 0; }
TSAH_HD uint32_t leafFirstSlot(int32_t ref) { return static_cast<uint32_t>(~ref); }
TSAH_HD int32_t makeLeafRef(uint32_t firstSlot) { return ~static_cast<int32_t>(firstSlot); }

// Largest triangle count a file or runtime accepts: slots must be encodable as ~slot in int32.
inline constexpr uint32_t kMaxGpuTriangles = 0x7fffffffu;

}  // namespace tsah
