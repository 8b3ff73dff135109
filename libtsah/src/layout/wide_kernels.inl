// The wide traversal kernels, written once against a small SIMD type V (V::N lanes) and included
// by each wide_kernels_<isa>.cpp inside its own namespace, after it has defined V4 / V8 for its
// instruction set. No includes here: everything this needs is included by the including file.
//
// V provides: set1, load (aligned), store, + - * /, min, max, abs, comparisons lt/le/gt returning
// V::Mask, Mask & | and andNot(a, b) = ~a & b, and bits(mask) (one bit per lane).
//
// Every entry point is `flatten`, so the shared inline helpers (prepareSlabs, intersectBox,
// intersectWatertight) are inlined into it and no copy of them compiled for this instruction set
// is emitted for the linker to pick for other files.
//
// The arithmetic is the scalar code's (traversal.hpp, woop.hpp), operation for operation, so with
// FMA contraction off (the files' flags) every box and triangle result is bit-identical to it.

#define TSAH_KERNEL [[gnu::flatten]]

// The ray's RayPrep: the slab part at once, the watertight shear on the first fallback to the
// watertight test (most rays never need it, and its axis choice is a data-dependent branch).
struct LazyPrep {
  RayPrep prep;
  bool shear = false;
  // The shear fields start at zero only so that no path reads an indeterminate value as far as the
  // compiler can tell (watertight() always fills them before they are used).
  explicit LazyPrep(const Ray& ray) : prep(prepareSlabs(ray)) {
    prep.kx = prep.ky = prep.kz = 0;
    prep.sx = prep.sy = prep.sz = 0.0f;
  }
  const RayPrep& watertight(const Ray& ray) {
    if (!shear) prepareShear(ray, prep), shear = true;
    return prep;
  }
};

// False for a ray with a NaN or infinite origin or direction component (or components beyond
// +-1e38, whose sum leaves the float range): such a ray hits nothing. Its slab distances would be
// NaN, which the node test's max and min drop, so it would enter unused child slots (a NaN origin
// walked off the stack). x - x is 0 for a finite x and NaN otherwise. A NaN tmin or tmax needs no
// test: traverse takes them as the max's and min's second operand, which a NaN wins, and culls.
inline bool traceable(const Ray& ray) {
  const float sum = ((ray.org.x + ray.org.y) + ray.org.z) + ((ray.dir.x + ray.dir.y) + ray.dir.z);
  return sum - sum == 0.0f;
}

// Per-ray values broadcast to all lanes.
template <class V>
struct RayLanes {
  V org[3], dir[3], inv[3];
  V negOrg[3];                         // -org: plane + (-org) rounds as plane - org, and the sum takes
                                       // the plane straight from memory (a difference cannot)
  uint32_t nearPlane[3], farPlane[3];  // rows of WideSoaNode::box holding each axis's near/far plane
  V nearPadSign[3];                    // blurred boxes: -1 where the near plane is lo, else +1 (slabDistances)
  V f, g;                              // blurred: the ray's place between the keys, and 1 - f
};

template <class V>
inline RayLanes<V> rayLanes(const Ray& ray, const RayPrep& prep, float f) {
  RayLanes<V> r;
  r.f = V::set1(f);
  r.g = V::set1(1.0f) - r.f;
  for (int a = 0; a < 3; ++a) {
    r.org[a] = V::set1(ray.org[a]);
    r.negOrg[a] = V::set1(-ray.org[a]);
    r.dir[a] = V::set1(ray.dir[a]);
    r.inv[a] = V::set1(prep.invDir[a]);
    r.nearPlane[a] = prep.invDir[a] >= 0.0f ? uint32_t(a) : uint32_t(a + 3);
    r.farPlane[a] = prep.invDir[a] >= 0.0f ? uint32_t(a + 3) : uint32_t(a);
    r.nearPadSign[a] = V::set1(prep.invDir[a] >= 0.0f ? -1.0f : 1.0f);
  }
  return r;
}

// dot(p, row r of the packet's triangles) as the scalar code evaluates it: (x*rx + y*ry) + z*rz.
template <class V, uint32_t N>
inline V dotRow(const V p[3], const WoopPacket<N>& pk, int r) {
  return p[0] * V::load(pk.row[4 * r]) + p[1] * V::load(pk.row[4 * r + 1]) + p[2] * V::load(pk.row[4 * r + 2]);
}
// ((start + |x*rx|) + |y*ry|) + |z*rz|, the scalar code's order for its error bounds.
template <class V, uint32_t N>
inline V absDotRow(V start, const V p[3], const WoopPacket<N>& pk, int r) {
  return start + V::abs(p[0] * V::load(pk.row[4 * r])) + V::abs(p[1] * V::load(pk.row[4 * r + 1])) +
         V::abs(p[2] * V::load(pk.row[4 * r + 2]));
}
// (|x*rx| + |y*ry|) + |z*rz|.
template <class V, uint32_t N>
inline V absDotRow(const V p[3], const WoopPacket<N>& pk, int r) {
  return V::abs(p[0] * V::load(pk.row[4 * r])) + V::abs(p[1] * V::load(pk.row[4 * r + 1])) +
         V::abs(p[2] * V::load(pk.row[4 * r + 2]));
}

// The triangles of one leaf (packets [first, first + packetCount(count))). Returns true when one
// was hit; for closest hit tmax shrinks to it. hit.tri is the hit's slot, not its triangle: any hit
// only asks whether something was hit, and closest hit maps the final slot once (traverseTriangles).
// Looking the triangle up at every hit was one more dependent load, a cache miss on large trees.
template <class V, bool AnyHit>
inline bool intersectLeaf(const WideView<V::N>& bvh, const Ray& ray, LazyPrep& prep, const RayLanes<V>& r,
                          uint32_t first, uint32_t count, float& tmax, Hit& hit) {
  constexpr uint32_t N = V::N;
  bool found = false;
  const V tmin = V::set1(ray.tmin);
  for (uint32_t p = 0; p < packetCount<N>(count); ++p) {
    const WoopPacket<N>& pk = bvh.packets[first + p];
    const uint32_t lanes = count - p * N < N ? count - p * N : N;
    const uint32_t used = (1u << lanes) - 1u;
    const V r0w = V::load(pk.row[3]);
    const V oz = r0w - dotRow(r.org, pk, 0);
    const V dz = dotRow(r.dir, pk, 0);
    const V tt = oz / dz;
    const auto inRange = V::gt(tt, tmin) & V::lt(tt, V::set1(tmax));
    const V r0abs = V::abs(V::load(pk.row[0])) + V::abs(V::load(pk.row[1])) + V::abs(V::load(pk.row[2]));
    const auto grazing = V::andNot(inRange, V::lt(V::abs(dz), V::set1(1e-12f) * r0abs));
    if (!((V::bits(inRange) | V::bits(grazing)) & used)) continue;  // no lane can hit: skip the rest
    // Barycentrics and their error bounds (woop.hpp's intersectTriangle).
    const V du = dotRow(r.dir, pk, 1), dv = dotRow(r.dir, pk, 2);
    const V b0 = (V::load(pk.row[7]) + dotRow(r.org, pk, 1)) + tt * du;
    const V b1 = (V::load(pk.row[11]) + dotRow(r.org, pk, 2)) + tt * dv;
    const V b2 = (V::set1(1.0f) - b0) - b1;
    const V absT = V::abs(tt);
    const V errT = absDotRow(V::abs(r0w), r.org, pk, 0) / V::abs(dz);
    const V e0 = (absDotRow(V::abs(V::load(pk.row[7])), r.org, pk, 1) + absT * absDotRow(r.dir, pk, 1)) +
                 errT * V::abs(du);
    const V e1 = (absDotRow(V::abs(V::load(pk.row[11])), r.org, pk, 2) + absT * absDotRow(r.dir, pk, 2)) +
                 errT * V::abs(dv);
    const V band0 = V::max(V::set1(kWoopEdgeBand), V::set1(kWoopErrorScale) * e0);
    const V band1 = V::max(V::set1(kWoopEdgeBand), V::set1(kWoopErrorScale) * e1);
    const V band2 = band0 + band1;
    const V zero = V::set1(0.0f);
    const auto reject = V::lt(b0, zero - band0) | V::lt(b1, zero - band1) | V::lt(b2, zero - band2);
    const auto accept = V::gt(b0, band0) & V::gt(b1, band1) & V::gt(b2, band2);
    uint32_t hits = V::bits(inRange & accept) & used;
    uint32_t fallback = (V::bits(V::andNot(reject | accept, inRange)) | V::bits(grazing)) & used;
    if (hits) {
      if (AnyHit) {
        const uint32_t lane = uint32_t(__builtin_ctz(hits));
        hit.t = 0.0f;
        hit.tri = pk.slot[lane];
        return true;
      }
      alignas(32) float t[N], u[N], v[N];
      V::store(t, tt);
      V::store(u, b1);
      V::store(v, b2);
      uint32_t best = uint32_t(__builtin_ctz(hits));
      for (uint32_t m = hits & (hits - 1); m; m &= m - 1) {
        const uint32_t lane = uint32_t(__builtin_ctz(m));
        if (t[lane] < t[best]) best = lane;
      }
      tmax = t[best];
      hit = {t[best], u[best], v[best], pk.slot[best]};
      found = true;
    }
    for (; fallback; fallback &= fallback - 1) {  // near an edge, or grazing: the watertight test decides
      const uint32_t slot = pk.slot[__builtin_ctz(fallback)];
      const uint32_t* tri = bvh.slotVertices + 3 * std::size_t(slot);  // no triIndex load before the vertices
      float t, u, v;
      if (intersectWatertight(prep.watertight(ray), bvh.vertex(tri[0]), bvh.vertex(tri[1]), bvh.vertex(tri[2]),
                              ray.tmin, tmax, t, u, v)) {
        tmax = t;
        hit = {t, u, v, slot};
        found = true;
        if (AnyHit) return true;
      }
    }
  }
  return found;
}

// The watertight test (intersectWatertight's operations lane by lane) on the leaf's packets of
// vertices: coordinates(p, c) fills c[3 * k + a] with coordinate a of vertex k of packet p's lanes,
// vertex(p, k, lane) gives one lane's vertex k for the scalar test. A lane whose U, V or W is not
// clearly nonzero in float takes the scalar test (its edge decision in double) on the same
// vertices. Of the lanes that hit, the nearest wins and the first lane among equal distances:
// what testing the slots one by one, each against the nearest hit so far, returns. hit.tri is the
// hit's slot, as in intersectLeaf.
template <class V, bool AnyHit, class Coordinates, class Vertex>
inline bool intersectVertexPackets(const uint32_t* packetSlots, const Ray& ray, LazyPrep& lazy, uint32_t first,
                                   uint32_t count, float& tmax, Hit& hit, Coordinates coordinates, Vertex vertex) {
  constexpr uint32_t N = V::N;
  const RayPrep& prep = lazy.watertight(ray);
  const V zero = V::set1(0.0f);
  const V sx = V::set1(prep.sx), sy = V::set1(prep.sy), sz = V::set1(prep.sz);
  const int axis[3] = {prep.kx, prep.ky, prep.kz};
  V org[3];
  for (int i = 0; i < 3; ++i) org[i] = V::set1(prep.org[axis[i]]);
  const auto nonzero = [&](V x) { return V::lt(x, zero) | V::gt(x, zero); };
  bool found = false;
  for (uint32_t p = 0; p < packetCount<N>(count); ++p) {
    const uint32_t lanes = count - p * N < N ? count - p * N : N;
    const uint32_t used = (1u << lanes) - 1u;
    V c[9];
    coordinates(first + p, c);
    // Vertex k relative to the origin in the ray's axes, then sheared (x, y) and scaled (z).
    V x[3], y[3], z[3];
    for (int k = 0; k < 3; ++k) {
      V rel[3];
      for (int i = 0; i < 3; ++i) rel[i] = c[3 * k + axis[i]] - org[i];
      x[k] = rel[0] - sx * rel[2];
      y[k] = rel[1] - sy * rel[2];
      z[k] = sz * rel[2];
    }
    const V U = x[2] * y[1] - y[2] * x[1];
    const V Vb = x[0] * y[2] - y[0] * x[2];
    const V W = x[1] * y[0] - y[1] * x[0];
    const uint32_t fallback = ~V::bits(nonzero(U) & nonzero(Vb) & nonzero(W)) & used;
    const auto negative = V::lt(U, zero) | V::lt(Vb, zero) | V::lt(W, zero);
    const auto positive = V::gt(U, zero) | V::gt(Vb, zero) | V::gt(W, zero);
    const V det = U + Vb + W;
    const V T = U * z[0] + Vb * z[1] + W * z[2];
    const V rcp = V::set1(1.0f) / det;
    const V tt = T * rcp;
    const auto inRange = V::gt(tt, V::set1(ray.tmin)) & V::lt(tt, V::set1(tmax));
    uint32_t hits = V::bits(V::andNot(negative & positive, nonzero(det) & inRange)) & used & ~fallback;
    if (!(hits | fallback)) continue;
    const uint32_t slot0 = packetSlots[first + p];  // lane l holds slot slot0 + l
    if (AnyHit && hits) {
      hit.t = 0.0f;
      hit.tri = slot0 + uint32_t(__builtin_ctz(hits));
      return true;
    }
    alignas(32) float t[N], u[N], v[N];
    V::store(t, tt);
    V::store(u, Vb * rcp);
    V::store(v, W * rcp);
    for (uint32_t rest = fallback; rest; rest &= rest - 1) {
      const uint32_t lane = uint32_t(__builtin_ctz(rest));
      const auto at = [&](uint32_t k) { return vertex(first + p, k, lane); };
      if (intersectWatertight(prep, at(0), at(1), at(2), ray.tmin, tmax, t[lane], u[lane], v[lane])) {
        if (AnyHit) {
          hit.t = 0.0f;
          hit.tri = slot0 + lane;
          return true;
        }
        hits |= 1u << lane;
      }
    }
    if (!hits) continue;
    uint32_t best = uint32_t(__builtin_ctz(hits));
    for (uint32_t rest = hits & (hits - 1); rest; rest &= rest - 1) {
      const uint32_t lane = uint32_t(__builtin_ctz(rest));
      if (t[lane] < t[best]) best = lane;
    }
    tmax = t[best];
    hit = {t[best], u[best], v[best], slot0 + best};
    found = true;
  }
  return found;
}

// A leaf of a tree in the Vertices form (TriangleForm): the view's vertex packets of this frame.
template <class V, bool AnyHit>
inline bool intersectVertexLeaf(const WideView<V::N>& bvh, const Ray& ray, LazyPrep& lazy, uint32_t first,
                                uint32_t count, float& tmax, Hit& hit) {
  return intersectVertexPackets<V, AnyHit>(
      bvh.packetSlots, ray, lazy, first, count, tmax, hit,
      [&](uint32_t p, V c[9]) {
        for (int row = 0; row < 9; ++row) c[row] = V::load(bvh.vertexPackets[p].vertex[row]);
      },
      [&](uint32_t p, uint32_t k, uint32_t lane) { return bvh.vertexPackets[p].get(k, lane); });
}

// A blurred leaf: each slot's triangle lerped at f between the two keys' vertex packets
// (motion::lerpVertex's operations lane by lane), then the vertex packets' test.
template <class V, bool AnyHit>
inline bool intersectMotionLeaf(const WideView<V::N>& bvh, const WideMotionFrame<V::N>& m, const Ray& ray,
                                LazyPrep& lazy, const RayLanes<V>& r, uint32_t first, uint32_t count, float& tmax,
                                Hit& hit) {
  return intersectVertexPackets<V, AnyHit>(
      bvh.packetSlots, ray, lazy, first, count, tmax, hit,
      [&](uint32_t p, V c[9]) {
        for (int row = 0; row < 9; ++row)
          c[row] = motion::lerpOf(V::load(m.vertices0[p].vertex[row]), V::load(m.vertices1[p].vertex[row]), r.f, r.g);
      },
      [&](uint32_t p, uint32_t k, uint32_t lane) {
        return motion::lerpVertex(m.vertices0[p].get(k, lane), m.vertices1[p].get(k, lane), m.f);
      });
}

// A node's entry and exit distances on each axis, (plane - org) * inv (as plane + (-org), the same
// rounding) for the near and the far plane as the ray's sign picks them (RayLanes): the planes
// loaded, or (blurred) lerped between the two keys and padded outward, motion::lerpBox's operations lane by lane in its order. The planes
// are loaded by the ray's plane index straight from the nodes and used axis by axis, so the lerped
// values stay in registers (a six-row array indexed by plane would live on the stack). The pad is
// subtracted from a lo plane and added to a hi plane: the ray's signed pad (RayLanes::nearPadSign,
// -1 where the near plane is lo) is added to the near plane and subtracted from the far plane,
// which rounds exactly as lerpBox's lo - pad and hi + pad (negation is exact).
template <class V, bool Blurred>
inline void slabDistances(const WideSoaNode<V::N>& node, const WideMotionFrame<V::N>& m, int32_t ref,
                          const RayLanes<V>& r, V tNear[3], V tFar[3]) {
  for (int a = 0; a < 3; ++a) {
    V nearPlane, farPlane;
    if constexpr (!Blurred) {
      nearPlane = V::load(node.box[r.nearPlane[a]]);
      farPlane = V::load(node.box[r.farPlane[a]]);
    } else {
      const WideSoaNode<V::N>& node1 = m.nodes1[ref];
      const V near0 = V::load(node.box[r.nearPlane[a]]), far0 = V::load(node.box[r.farPlane[a]]);
      const V near1 = V::load(node1.box[r.nearPlane[a]]), far1 = V::load(node1.box[r.farPlane[a]]);
      const V mag = V::max(V::max(V::abs(near0), V::abs(far0)), V::max(V::abs(near1), V::abs(far1)));
      const V pad = motion::padOf(mag, V::set1(motion::kPadPerMagnitude), V::set1(motion::kPadFloor));
      const V signedPad = pad * r.nearPadSign[a];
      nearPlane = motion::lerpOf(near0, near1, r.f, r.g) + signedPad;
      farPlane = motion::lerpOf(far0, far1, r.f, r.g) - signedPad;
    }
    tNear[a] = (nearPlane + r.negOrg[a]) * r.inv[a];
    tFar[a] = (farPlane + r.negOrg[a]) * r.inv[a];
  }
}

// Starts loading an entered child that goes on the stack, so that its lines are on their way while
// the nodes above it in the stack are traversed (a pushed child is read later, often after its
// lines would have missed the cache): an interior child's node, a leaf's first packet (its first
// lines: the Woop packet's rows the early exit reads and the next ones). Only a hint: the results
// do not depend on it. A blurred leaf (two keys' packets) is not prefetched. A visitor's traversal
// (the TLAS, small enough to stay in cache) prefetches nothing (traverse's Prefetch).
template <uint32_t N, bool Blurred>
struct ChildPrefetch {
  const char* nodes;
  const char* leaves;  // the view's packets in its triangle form
  std::size_t leafStride;

  explicit ChildPrefetch(const WideView<N>& bvh)
      : nodes(reinterpret_cast<const char*>(bvh.nodes)),
        leaves(bvh.packets != nullptr ? reinterpret_cast<const char*>(bvh.packets)
                                      : reinterpret_cast<const char*>(bvh.vertexPackets)),
        leafStride(bvh.packets != nullptr ? sizeof(WoopPacket<N>) : sizeof(KeyVertexPacket<N>)) {}
  // Always inlined: as a call of its own GCC finds it free of side effects and drops it.
  [[gnu::always_inline]] void operator()(int32_t ref) const {
    if constexpr (Blurred)
      if (isLeafRef(ref)) return;
    // The address is chosen without a branch (a leaf or a node, unpredictable).
    const char* at = isLeafRef(ref) ? leaves + std::size_t(leafFirstSlot(ref)) * leafStride
                                    : nodes + std::size_t(uint32_t(ref)) * sizeof(WideSoaNode<N>);
    constexpr uint32_t kLines = N >= 8 ? 4 : 2;  // a node: 256 or 128 bytes
    for (uint32_t line = 0; line < kLines; ++line) __builtin_prefetch(at + 64 * line);
  }
};

// What a traversal looks for, and for any hit in which order it visits the entered children.
enum class Query { Closest, AnyFarthestFirst, AnyTreeOrder };

// Blurred: bvh holds key s (nodes, positions, the lerped root box) and m key s + 1 (see
// WideMotionFrame); otherwise m is not read. leafTest(prep, lanes, first, count, tmax, hit) tests
// a leaf's primitives and returns true when one was hit (closest hit: tmax shrunk to it); the
// triangle kernels pass their leaf tests, the visitor kernels the caller's visitor. rootFirst: a
// box holding every child box of an interior root, tested before the ray's lanes are set up (a
// ray missing it misses every child box the loop would test: the slab test is monotone in the
// planes). For closest hit only: the camera's rays, many of which miss a small scene; an any-hit
// ray (a shadow or ambient-occlusion ray) leaves a surface inside that box, so the test would only
// cost it time. Prefetch: pushed children are prefetched (ChildPrefetch).
template <class V, Query Q, bool Blurred = false, bool Prefetch = true, class LeafTest>
inline Hit traverse(const WideView<V::N>& bvh, const WideMotionFrame<V::N>& m, const Ray& ray, LeafTest&& leafTest,
                    const Aabb* rootFirst = nullptr) {
  constexpr uint32_t N = V::N;
  constexpr bool AnyHit = Q != Query::Closest;
  Hit hit;
  if (bvh.rootCount == 0 && isLeafRef(bvh.rootRef)) return hit;  // empty tree
  if (!traceable(ray)) return hit;
  LazyPrep prep(ray);
  float tmax = ray.tmax;
  if (rootFirst != nullptr) {  // a constant once inlined: no branch where it is null
    float tEntry;
    if (!isLeafRef(bvh.rootRef) && !intersectBox(prep.prep, *rootFirst, ray.tmin, tmax, tEntry)) return hit;
  }
  const RayLanes<V> r = rayLanes<V>(ray, prep.prep, Blurred ? m.f : 0.0f);
  if (isLeafRef(bvh.rootRef)) {
    float tEntry;
    if (!intersectBox(prep.prep, bvh.rootBox, ray.tmin, tmax, tEntry)) return hit;
    leafTest(prep, r, leafFirstSlot(bvh.rootRef), bvh.rootCount, tmax, hit);
    return hit;
  }
  // An interior root's box is not tested: it is the union of its children's boxes, and the slab
  // test is monotone in the planes (rounding included), so a ray missing the root box misses every
  // child box too; the child tests below decide exactly as if the root test had come first.
  struct Entry {
    int32_t ref;
    uint32_t count;
    float t;  // sort key; closest hit: the entry distance, skipped once the hit is nearer
  };
  Entry stack[kWideStackSize];
  uint32_t sp = 0;
  int32_t ref = bvh.rootRef;
  uint32_t count = 0;
  const V vtmin = V::set1(ray.tmin);
  const V farScale = V::set1(kSlabFarScale);
  const ChildPrefetch<N, Blurred> prefetchChild(bvh);
  for (;;) {
    if (!isLeafRef(ref)) {
      const WideSoaNode<N>& node = bvh.nodes[ref];
      V tNear[3], tFar[3];
      slabDistances<V, Blurred>(node, m, ref, r, tNear, tFar);
      // The limits as second operands: a NaN tmin or tmax wins (a > b ? a : b) and culls (traceable).
      const V tn = V::max(V::max(tNear[0], tNear[1]), V::max(tNear[2], vtmin));
      const V tf = V::min(V::min(tFar[0], tFar[1]), V::min(tFar[2], V::set1(tmax))) * farScale;
      uint32_t mask = V::bits(V::le(tn, tf));
      if (mask) {
        const uint32_t c0 = uint32_t(__builtin_ctz(mask));
        mask &= mask - 1;
        if (!mask) {  // one child: no ordering needed
          ref = node.ref[c0];
          count = node.count[c0];
          continue;
        }
        if constexpr (Q == Query::AnyTreeOrder) {  // every entered child in slot order; the last one next
          for (uint32_t c = c0;;) {
            if constexpr (Prefetch) prefetchChild(node.ref[c]);
            stack[sp++] = Entry{node.ref[c], node.count[c], 0.0f};
            if (!mask) break;
            c = uint32_t(__builtin_ctz(mask));
            mask &= mask - 1;
          }
          --sp;
          ref = stack[sp].ref;
          count = stack[sp].count;
          continue;
        }
        // Push every entered child, the pushed block sorted by key; continue with the top one.
        // Closest hit: nearest first (the key is the entry distance). Any hit: farthest first (the
        // key is its negation). An occlusion ray leaves a surface: its nearest boxes hold that
        // surface, which it moves away from, while an occluder lies across the gap (a wall, a
        // ceiling, another object); a ray that finds nothing visits every entered child anyway.
        // With tied keys the block keeps slot order, the last slot on top (TreeOrder's order).
        alignas(32) float key[N];
        V::store(key, AnyHit ? V::set1(0.0f) - tn : tn);
        if (!(mask & (mask - 1))) {  // two children: the insertion's order with one compare
          const uint32_t c1 = uint32_t(__builtin_ctz(mask));
          const bool swap = key[c0] < key[c1];
          const uint32_t below = swap ? c1 : c0, first = swap ? c0 : c1;
          if constexpr (Prefetch) prefetchChild(node.ref[below]);
          stack[sp++] = Entry{node.ref[below], node.count[below], key[below]};
          ref = node.ref[first];
          count = node.count[first];
          continue;
        }
        const uint32_t base = sp;
        for (uint32_t c = c0;;) {
          if constexpr (Prefetch) prefetchChild(node.ref[c]);
          const Entry e{node.ref[c], node.count[c], key[c]};
          uint32_t i = sp++;
          while (i > base && stack[i - 1].t < e.t) {
            stack[i] = stack[i - 1];
            --i;
          }
          stack[i] = e;
          if (!mask) break;
          c = uint32_t(__builtin_ctz(mask));
          mask &= mask - 1;
        }
        --sp;
        ref = stack[sp].ref;
        count = stack[sp].count;
        continue;
      }
    } else {
      if (leafTest(prep, r, leafFirstSlot(ref), count, tmax, hit) && AnyHit) return hit;
    }
    do {
      if (sp == 0) return hit;
      --sp;
    } while (!AnyHit && stack[sp].t > tmax * kSlabFarScale);  // any hit: tmax never shrinks
    ref = stack[sp].ref;
    count = stack[sp].count;
  }
}

// --- Refit: the Woop rows and the box of one packet ----------------------------------------------
// makeWoopTriangle's double-precision arithmetic (woopRowsDouble) on all N lanes at once, as GCC
// vectors of N doubles (one AVX-512 register for 8 lanes; pairs / quads of registers below that).
typedef double DoubleLanes4 __attribute__((vector_size(4 * sizeof(double))));
typedef double DoubleLanes8 __attribute__((vector_size(8 * sizeof(double))));
typedef float FloatLanes4 __attribute__((vector_size(4 * sizeof(float))));
typedef float FloatLanes8 __attribute__((vector_size(8 * sizeof(float))));
typedef int32_t IntLanes4 __attribute__((vector_size(4 * sizeof(int32_t))));
typedef int32_t IntLanes8 __attribute__((vector_size(8 * sizeof(int32_t))));

// One vertex's x, y, z (lane 3 zero) in one load. With AVX a masked load: it reads only the three
// floats, so the last vertex of an array is safe; without it, three scalar loads.
inline FloatLanes4 loadVertexXyz(const float* p) {
#if defined(__AVX__)
  return (FloatLanes4)_mm_maskload_ps(p, _mm_setr_epi32(-1, -1, -1, 0));
#else
  return FloatLanes4{p[0], p[1], p[2], 0.0f};
#endif
}

// Vertex k of every lane's triangle as three coordinate vectors: one load per lane, then a
// transpose in registers. (Not lane by lane from scalar loads, 8 loads and 8 inserts per
// coordinate; and not through a stack array written lane by lane and read as one vector: that load
// cannot take its data from the pending narrow stores and waits until they reach the cache, which
// is behind the previous packet's stores, usually cache misses.)
inline void transposeVertices(const FloatLanes4 (&v)[4], FloatLanes4 f[3]) {
  const FloatLanes4 xy01 = __builtin_shufflevector(v[0], v[1], 0, 4, 1, 5);  // x0 x1 y0 y1
  const FloatLanes4 xy23 = __builtin_shufflevector(v[2], v[3], 0, 4, 1, 5);
  const FloatLanes4 z01 = __builtin_shufflevector(v[0], v[1], 2, 6, 3, 7);  // z0 z1 0 0
  const FloatLanes4 z23 = __builtin_shufflevector(v[2], v[3], 2, 6, 3, 7);
  f[0] = __builtin_shufflevector(xy01, xy23, 0, 1, 4, 5);
  f[1] = __builtin_shufflevector(xy01, xy23, 2, 3, 6, 7);
  f[2] = __builtin_shufflevector(z01, z23, 0, 1, 4, 5);
}
inline void transposeVertices(const FloatLanes4 (&v)[8], FloatLanes8 f[3]) {
  FloatLanes8 w[4];  // lanes l and l + 4 side by side: the 4-lane transpose in both halves at once
  for (int l = 0; l < 4; ++l) w[l] = __builtin_shufflevector(v[l], v[l + 4], 0, 1, 2, 3, 4, 5, 6, 7);
  const FloatLanes8 xy01 = __builtin_shufflevector(w[0], w[1], 0, 8, 1, 9, 4, 12, 5, 13);
  const FloatLanes8 xy23 = __builtin_shufflevector(w[2], w[3], 0, 8, 1, 9, 4, 12, 5, 13);
  const FloatLanes8 z01 = __builtin_shufflevector(w[0], w[1], 2, 10, 3, 11, 6, 14, 7, 15);
  const FloatLanes8 z23 = __builtin_shufflevector(w[2], w[3], 2, 10, 3, 11, 6, 14, 7, 15);
  f[0] = __builtin_shufflevector(xy01, xy23, 0, 1, 8, 9, 4, 5, 12, 13);
  f[1] = __builtin_shufflevector(xy01, xy23, 2, 3, 10, 11, 6, 7, 14, 15);
  f[2] = __builtin_shufflevector(z01, z23, 0, 1, 8, 9, 4, 5, 12, 13);
}

// The nine coordinate vectors of a packet's lanes (f[3 * k + a]: coordinate a of vertex k); lanes
// from `lanes` on repeat lane 0's triangle (finite values, masked out by the callers).
template <uint32_t N, class F>
inline void gatherPacket(const float* positions, const uint32_t* vertices, uint32_t lanes, F f[9]) {
#pragma GCC unroll 3
  for (int k = 0; k < 3; ++k) {
    FloatLanes4 v[N];
#pragma GCC unroll 8
    for (uint32_t lane = 0; lane < N; ++lane) {
      const uint32_t source = lane & (0u - uint32_t(lane < lanes));  // lane, or 0 for padding: no branch
      v[lane] = loadVertexXyz(positions + 3 * std::size_t(vertices[3 * source + k]));
    }
    transposeVertices(v, f + 3 * k);
  }
}

// The lanes rotated by Half: lane i takes lane (i + Half) mod N (constant shuffles, one instruction).
// A template on the vector type, so that the 8-lane form exists only where it is used; through
// references, as a vector returned by value in a file without AVX changes the ABI.
template <uint32_t Half, class F>
inline void rotateLanes(const F& x, F& out) {
  if constexpr (sizeof(F) == 4 * sizeof(float)) {
    if constexpr (Half == 2) out = __builtin_shufflevector(x, x, 2, 3, 0, 1);
    else out = __builtin_shufflevector(x, x, 1, 2, 3, 0);
  } else {
    if constexpr (Half == 4) out = __builtin_shufflevector(x, x, 4, 5, 6, 7, 0, 1, 2, 3);
    else if constexpr (Half == 2) out = __builtin_shufflevector(x, x, 2, 3, 4, 5, 6, 7, 0, 1);
    else out = __builtin_shufflevector(x, x, 1, 2, 3, 4, 5, 6, 7, 0);
  }
}
// Lane 0 of lo / hi becomes the minimum / maximum over all lanes, by halving rotations.
template <uint32_t Half, class F>
inline void foldLanes(F& lo, F& hi) {
  F l, h;
  rotateLanes<Half>(lo, l);
  rotateLanes<Half>(hi, h);
  lo = l < lo ? l : lo;
  hi = h > hi ? h : hi;
  if constexpr (Half > 1) foldLanes<Half / 2>(lo, hi);
}

// The box of a gathered packet's triangles (padding lanes repeat lane 0): lane-wise over the three
// vertices (x < lo ? x : lo from the empty box, as the scalar refit compared, so a NaN coordinate
// is skipped), then across the lanes by halving rotations.
template <uint32_t N, class F>
inline Aabb packetBounds(const F f[9]) {
  Aabb bounds;
#pragma GCC unroll 3
  for (int a = 0; a < 3; ++a) {
    F lo = F{} + 3.402823466e38f, hi = F{} - 3.402823466e38f;
#pragma GCC unroll 3
    for (int k = 0; k < 3; ++k) {
      const F x = f[3 * k + a];
      lo = x < lo ? x : lo;
      hi = x > hi ? x : hi;
    }
    foldLanes<N / 2>(lo, hi);
    bounds.lo[a] = lo[0];
    bounds.hi[a] = hi[0];
  }
  return bounds;
}

template <uint32_t N, class D, class F, class I>
TSAH_KERNEL void woopRowsKernel(const float* positions, const uint32_t* vertices, uint32_t lanes, WoopPacket<N>& pk,
                                Aabb& bounds) {
  F f[9];
  gatherPacket<N>(positions, vertices, lanes, f);
  D v[3][3];
#pragma GCC unroll 9
  for (int k = 0; k < 3; ++k)
#pragma GCC unroll 3
    for (int a = 0; a < 3; ++a) v[k][a] = __builtin_convertvector(f[3 * k + a], D);
  D rows[12], nn;
  woopRowsDouble(v[0], v[1], v[2], rows, nn);
  I keep;  // all ones for the lanes that get their rows, zero for padding and degenerate triangles
  for (uint32_t lane = 0; lane < N; ++lane) keep[lane] = lane < lanes && woopNondegenerate(nn[lane]) ? -1 : 0;
  for (int r = 0; r < 12; ++r) {
    const F row = __builtin_convertvector(rows[r], F);
    I bits;
    std::memcpy(&bits, &row, sizeof bits);
    bits &= keep;
    std::memcpy(pk.row[r], &bits, sizeof bits);
  }
  bounds = packetBounds<N, F>(f);
}

// The blurred refit's step at one key: the packet's vertices (KeyVertexPacket) and their box, no
// Woop rows.
template <uint32_t N, class F>
TSAH_KERNEL void keyVerticesKernel(const float* positions, const uint32_t* vertices, uint32_t lanes,
                                   KeyVertexPacket<N>& out, Aabb& bounds) {
  F f[9];
  gatherPacket<N>(positions, vertices, lanes, f);
#pragma GCC unroll 9
  for (int r = 0; r < 9; ++r) std::memcpy(out.vertex[r], &f[r], sizeof f[r]);  // nine vector stores
  bounds = packetBounds<N, F>(f);
}

// The triangle traversals: the leaf tests of the instant frame or of a blurred one. The leaf tests
// report slots; a closest hit's slot becomes its triangle here (an any hit's is only tested for
// validity by the entry points).
template <class V, Query Q, bool Blurred, bool VertexLeaves = false>
inline Hit traverseTriangles(const WideView<V::N>& bvh, const WideMotionFrame<V::N>& m, const Ray& ray) {
  constexpr bool AnyHit = Q != Query::Closest;
  Hit found = traverse<V, Q, Blurred>(bvh, m, ray,
                                 [&](LazyPrep& prep, const RayLanes<V>& r, uint32_t first, uint32_t count, float& tmax,
                                     Hit& hit) {
                                   if constexpr (Blurred)
                                     return intersectMotionLeaf<V, AnyHit>(bvh, m, ray, prep, r, first, count, tmax, hit);
                                   else if constexpr (VertexLeaves)
                                     return intersectVertexLeaf<V, AnyHit>(bvh, ray, prep, first, count, tmax, hit);
                                   else
                                     return intersectLeaf<V, AnyHit>(bvh, ray, prep, r, first, count, tmax, hit);
                                 },
                                 Blurred && Q == Query::Closest ? &m.rootBounds : nullptr);  // the segment's root box
  if (!AnyHit && found.valid()) found.tri = bvh.triIndex[found.tri];
  return found;
}

// The instant kernels of either triangle form (the view's: vertex packets or Woop packets).
template <class V>
TSAH_KERNEL Hit closestKernel(const WideView<V::N>& bvh, const Ray& ray) {
  return bvh.vertexPackets ? traverseTriangles<V, Query::Closest, false, true>(bvh, {}, ray)
                           : traverseTriangles<V, Query::Closest, false>(bvh, {}, ray);
}
template <class V>
TSAH_KERNEL bool anyKernel(const WideView<V::N>& bvh, const Ray& ray, AnyHitOrder order) {
  if (bvh.vertexPackets)
    return order == AnyHitOrder::TreeOrder
               ? traverseTriangles<V, Query::AnyTreeOrder, false, true>(bvh, {}, ray).valid()
               : traverseTriangles<V, Query::AnyFarthestFirst, false, true>(bvh, {}, ray).valid();
  return order == AnyHitOrder::TreeOrder ? traverseTriangles<V, Query::AnyTreeOrder, false>(bvh, {}, ray).valid()
                                         : traverseTriangles<V, Query::AnyFarthestFirst, false>(bvh, {}, ray).valid();
}
template <class V>
TSAH_KERNEL Hit closestMotionKernel(const WideView<V::N>& bvh, const WideMotionFrame<V::N>& m, const Ray& ray) {
  return traverseTriangles<V, Query::Closest, true>(bvh, m, ray);
}
template <class V>
TSAH_KERNEL bool anyMotionKernel(const WideView<V::N>& bvh, const WideMotionFrame<V::N>& m, const Ray& ray,
                                 AnyHitOrder order) {
  return order == AnyHitOrder::TreeOrder ? traverseTriangles<V, Query::AnyTreeOrder, true>(bvh, m, ray).valid()
                                         : traverseTriangles<V, Query::AnyFarthestFirst, true>(bvh, m, ray).valid();
}

// A tree of boxes whose leaf children each name one item (WideLeafVisitor): the node loop above,
// and at each entered leaf the visitor (not inlined: an instance's own traversal).
template <class V, Query Q>
inline Hit traverseVisited(const WideView<V::N>& bvh, const Ray& ray, const WideLeafVisitor& visitor) {
  return traverse<V, Q, false, false>(bvh, {}, ray,
                        [&](LazyPrep&, const RayLanes<V>&, uint32_t item, uint32_t, float& tmax, Hit& hit) {
                          return visitor.visit(visitor.context, item, ray, tmax, hit);
                        },
                        Q == Query::Closest ? &bvh.rootBox : nullptr);
}
template <class V>
TSAH_KERNEL Hit closestVisitKernel(const WideView<V::N>& bvh, const Ray& ray, const WideLeafVisitor& visitor) {
  return traverseVisited<V, Query::Closest>(bvh, ray, visitor);
}
template <class V>
TSAH_KERNEL bool anyVisitKernel(const WideView<V::N>& bvh, const Ray& ray, AnyHitOrder order,
                                const WideLeafVisitor& visitor) {
  return order == AnyHitOrder::TreeOrder ? traverseVisited<V, Query::AnyTreeOrder>(bvh, ray, visitor).valid()
                                         : traverseVisited<V, Query::AnyFarthestFirst>(bvh, ray, visitor).valid();
}

// This instruction set's kernels as the dispatch table: four-lane nodes always, eight-lane nodes
// when the set has an eight-lane type V8 (not void).
template <class V4, class V8>
WideKernels kernelTable(SimdIsa isa) {
  WideKernels k;
  k.isa = isa;
  k.closest4 = &closestKernel<V4>;
  k.any4 = &anyKernel<V4>;
  k.closestMotion4 = &closestMotionKernel<V4>;
  k.anyMotion4 = &anyMotionKernel<V4>;
  if constexpr (!std::is_void_v<V8>) {
    k.closest8 = &closestKernel<V8>;
    k.any8 = &anyKernel<V8>;
    k.closestMotion8 = &closestMotionKernel<V8>;
    k.anyMotion8 = &anyMotionKernel<V8>;
  }
  k.woopRows4 = &woopRowsKernel<4, DoubleLanes4, FloatLanes4, IntLanes4>;
  k.woopRows8 = &woopRowsKernel<8, DoubleLanes8, FloatLanes8, IntLanes8>;
  k.keyVertices4 = &keyVerticesKernel<4, FloatLanes4>;
  k.keyVertices8 = &keyVerticesKernel<8, FloatLanes8>;
  return k;
}

// This instruction set's visitor kernels (wide_visit.hpp), the widths of kernelTable.
template <class V4, class V8>
WideVisitKernels visitKernelTable() {
  WideVisitKernels k;
  k.closest4 = &closestVisitKernel<V4>;
  k.any4 = &anyVisitKernel<V4>;
  if constexpr (!std::is_void_v<V8>) {
    k.closest8 = &closestVisitKernel<V8>;
    k.any8 = &anyVisitKernel<V8>;
  }
  return k;
}

#undef TSAH_KERNEL
