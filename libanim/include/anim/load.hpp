#pragma once
// One entry point for every input form the toolkit accepts.
#include <string>

#include "anim/animation.hpp"
#include "anim/load_options.hpp"

namespace anim {

// Loads INPUT, which may be:
//  - a .tanim file (the native binary format),
//  - a JSON manifest (.json) listing mesh files with optional times,
//  - a directory of mesh files (sorted by frame number, so 10 comes after 9),
//  - a printf pattern such as frames/walk_%04d.obj, or a glob such as 'frames/*.obj',
//  - a single mesh in a format OpenMesh reads (OBJ, PLY, OFF, STL, OM): a one-frame animation,
//  - a mesh and a point cache of the same points, mesh.obj+cache.pc2 or +cache.mdd, or a manifest
//    {"mesh": "mesh.obj", "cache": "cache.pc2"} (see point_cache.hpp),
//  - a BART .aff scene or an animated model (MD2, glTF, FBX, Collada) where those importers exist,
//  - a scene file (.json with "objects", docs/scenes.md): objects composed and baked.
// Throws tsah::FileError naming the file and the problem.
Animation load(const std::string& input, const LoadOptions& options = {});

}  // namespace anim
