#pragma once
// Traversal of a wide tree of boxes only (wide_layout.hpp's nodes, no triangles) whose leaf children
// each name one item (ref = makeLeafRef(item), count 1), the item tested by the caller: a two-level
// runtime's top level, whose items are instances traced through their own trees. The node loop is
// the triangle kernels' (wide_traversal.hpp: the same SIMD box test, closest hit near first and
// skipping entries beyond the hit, any hit in the given order), compiled per instruction set with
// them.
#include <cstdint>

#include "tsah/core/ray.hpp"
#include "tsah/layout/wide_layout.hpp"
#include "tsah/layout/wide_traversal.hpp"

namespace tsah {

// What the kernels do at an entered leaf child: visit(context, item, ray, tmax, hit) tests the
// item against the ray in (ray.tmin, tmax) and returns true when it was hit; closest hit: it also
// shrinks tmax to the hit and fills `hit`, which the kernel returns. Any hit: the first true ends
// the traversal.
struct WideLeafVisitor {
  const void* context = nullptr;
  bool (*visit)(const void* context, uint32_t item, const Ray& ray, float& tmax, Hit& hit) = nullptr;
};

// The visitor kernels of one instruction set. The view's nodes, root reference, root box and root
// count are read, nothing else; the root box also for an interior root (closest hit tests it first,
// as the binary loop does: camera rays that miss the scene stop there). A width without kernels has null pointers (sse: no 8-wide).
struct WideVisitKernels {
  Hit (*closest4)(const WideView<4>& bvh, const Ray& ray, const WideLeafVisitor& visitor) = nullptr;
  bool (*any4)(const WideView<4>& bvh, const Ray& ray, AnyHitOrder order, const WideLeafVisitor& visitor) = nullptr;
  Hit (*closest8)(const WideView<8>& bvh, const Ray& ray, const WideLeafVisitor& visitor) = nullptr;
  bool (*any8)(const WideView<8>& bvh, const Ray& ray, AnyHitOrder order, const WideLeafVisitor& visitor) = nullptr;
};

// The visitor kernels of isa; throws tsah::ConfigError when it is not supported (isaSupported).
const WideVisitKernels& wideVisitKernels(SimdIsa isa);

}  // namespace tsah
