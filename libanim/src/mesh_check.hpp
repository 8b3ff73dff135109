#pragma once
// Our own checks of PLY and OFF files around OpenMesh's readers, which drop a face that references a
// missing vertex (or a degenerate one) without an error and allocate whatever a header claims.
#include <cstdint>
#include <span>
#include <string>

namespace anim {

struct DeclaredMesh {
  bool known = false;  // false for formats without a declared size (STL, OM)
  uint64_t vertices = 0, faces = 0;
};

// Reads the header of a PLY or OFF file (by its extension) and walks its vertices and faces:
// counts that cannot fit in the file, a non-numeric, non-finite or too large coordinate, a face
// with fewer than 3 vertices or one referencing a vertex that does not exist throw tsah::FileError
// naming the file and the vertex or face. Other extensions return {known = false}.
DeclaredMesh checkMeshFile(const std::string& path, std::span<const uint8_t> bytes);

}  // namespace anim
