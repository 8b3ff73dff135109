#pragma once
// The box of an affine image of a box, on the CPU and on the GPU alike (the two-level runtimes'
// instance boxes: the CPU's and the device's must be equal bit for bit).
#include <cmath>

#include "tsah/core/aabb.hpp"

namespace tsah {

// rows: the 3x4 affine map, row-major (x' = rows[0..3] . (x, y, z, 1), and so on). Each of the box's
// 8 corners is transformed in double and rounded to float, then widened by one ulp outward: the
// float box contains the float points that rays transformed into instance space are tested against.
// An empty box stays empty.
TSAH_HD Aabb transformBoxRows(const Aabb& box, const double* rows) {
  if (box.empty()) return box;
  Aabb out;
  for (int corner = 0; corner < 8; ++corner) {
    const double p[3] = {(corner & 1) ? box.hi.x : box.lo.x, (corner & 2) ? box.hi.y : box.lo.y,
                         (corner & 4) ? box.hi.z : box.lo.z};
    float q[3];
    for (int r = 0; r < 3; ++r)
      q[r] = float(rows[4 * r] * p[0] + rows[4 * r + 1] * p[1] + rows[4 * r + 2] * p[2] + rows[4 * r + 3]);
    out.extend(Vec3{nextafterf(q[0], -3.4e38f), nextafterf(q[1], -3.4e38f), nextafterf(q[2], -3.4e38f)});
    out.extend(Vec3{nextafterf(q[0], 3.4e38f), nextafterf(q[1], 3.4e38f), nextafterf(q[2], 3.4e38f)});
  }
  return out;
}

}  // namespace tsah
