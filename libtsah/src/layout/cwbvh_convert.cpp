// Host emulation of the GPU conversion of a binary tree into the compressed 8-wide layout
// (cwbvh_convert.hpp has the steps; cuda_kernels/src/cwbvh_rebuild.cu runs them on the device).
#include "tsah/layout/cwbvh_convert.hpp"

#include <algorithm>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"

namespace tsah {

CwbvhTree convertToCwbvh(const BinaryTreeView& t, int32_t rootRef, uint32_t rootCount, const Aabb& rootBox,
                         uint32_t mergeLimit) {
  if (t.triangles == 0) throw tsah::DataError("compressed wide BVH: the binary tree has no triangles");
  if (mergeLimit > kCwbvhMaxLeafTriangles)
    throw tsah::ConfigError("compressed wide BVH: leaves merge at most " + std::to_string(kCwbvhMaxLeafTriangles) +
                            " triangles");
  // Every wide node but a one-leaf root starts at its own binary interior node, and a binary tree
  // over n triangles has at most n - 1 of them: more means the references form no tree.
  const uint32_t maxNodes = std::max(1u, t.triangles - 1);
  CwbvhTree out;
  out.rootRef = 0;
  out.rootCount = 0;
  out.rootBox = rootBox;
  out.triIndex.assign(t.triangles, 0);
  std::vector<int32_t> starts{rootRef};
  out.parentSlot.assign(1, kCwbvhNoParent);
  std::vector<CwbvhOpening> level;
  uint32_t begin = 0, end = 1, depth = 0;
  uint64_t nodes = 1, tris = 0;
  for (; begin < end; begin = end, end = uint32_t(nodes), ++depth) {
    level.assign(end - begin, CwbvhOpening{});
    uint64_t interior = 0, leafTris = 0;
    for (uint32_t i = begin; i < end; ++i) {
      CwbvhOpening& o = level[i - begin];
      if (!cwbvhOpen(t, starts[i], i == 0 ? rootCount : 0u, rootBox, mergeLimit, o))
        throw tsah::DataError(
            "compressed wide BVH: the binary tree is invalid (a reference out of range, an empty "
            "leaf, or more than 64 triangles under one wide node)");
      interior += o.interior;
      leafTris += o.triangles;
      if (o.triangles > 0) out.depth = depth + 1;
    }
    if (nodes + interior > maxNodes || tris + leafTris > t.triangles)
      throw tsah::DataError("compressed wide BVH: the binary references do not form a tree over the triangles");
    out.nodes.resize(std::size_t(nodes + interior));
    out.parentSlot.resize(out.nodes.size(), kCwbvhNoParent);
    out.exactBoxes.resize(out.nodes.size() * kCwbvhWidth);
    starts.resize(out.nodes.size());
    CwbvhConvertOutput dst{out.nodes.data(), starts.data(), out.triIndex.data(), out.exactBoxes.data(),
                           out.parentSlot.data()};
    // The level's exclusive prefix sums, in node order (the GPU's scan).
    uint32_t childBase = uint32_t(nodes), triBase = uint32_t(tris);
    for (uint32_t i = begin; i < end; ++i) {
      const CwbvhOpening& o = level[i - begin];
      cwbvhWriteNode(t, o, i, childBase, triBase, dst);
      childBase += o.interior;
      triBase += o.triangles;
    }
    nodes += interior;
    tris += leafTris;
  }
  if (tris != t.triangles)
    throw tsah::DataError("compressed wide BVH: the binary tree's leaves hold " + std::to_string(tris) + " of " +
                          std::to_string(t.triangles) + " triangles");
  // The refit's leaf list: a node's leaves in slot order, each ending where the next begins.
  for (uint32_t i = 0; i < out.nodeCount(); ++i) {
    const CwbvhNode& n = out.nodes[i];
    uint32_t leafSlots[kCwbvhWidth], k = 0;
    for (uint32_t s = 0; s < kCwbvhWidth; ++s)
      if (n.isLeaf(s)) leafSlots[k++] = s;
    for (uint32_t j = 0; j < k; ++j) {
      const uint32_t first = n.leafOffset(leafSlots[j]);
      const uint32_t last = j + 1 < k ? n.leafOffset(leafSlots[j + 1]) : n.triCount;  // exclusive
      out.leaves.push_back({i * kCwbvhWidth + leafSlots[j], n.triBase + first, last - first});
    }
  }
  return out;
}

CwbvhTree convertToCwbvh(const FlatBvh& flat, uint32_t frame, uint32_t mergeLimit) {
  if (frame >= flat.frameCount || flat.rootBoxes.size() <= frame ||
      flat.nodes.size() < std::size_t(flat.frameCount) * flat.interiorCount)
    throw tsah::ConfigError("compressed wide BVH: the flat tree has no frame " + std::to_string(frame));
  const std::span<const GpuBvhNode> block = flat.frameNodes(frame);
  const BinaryTreeView view{block.data(), flat.interiorCount, flat.triIndex.data(), flat.triangleCount()};
  return convertToCwbvh(view, flat.rootRef, flat.rootCount, flat.rootBoxes[frame], mergeLimit);
}

}  // namespace tsah
