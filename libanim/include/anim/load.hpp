#pragma once
// One entry point for every input form the toolkit accepts.
#include <functional>
#include <string>

#include "anim/animation.hpp"

namespace anim {

struct LoadOptions {
  // Sampling rate for formats that store continuous animation (AFF, skeletal, morph targets);
  // 0 means the format's own frame rate / frame count.
  double fps = 0.0;
  // Which animation clip to bake when a file holds several (name or index); empty: the first.
  std::string clip;
  // Called as work progresses (done, total); may be empty. Libraries never print.
  std::function<void(std::size_t done, std::size_t total)> progress;
  // Called with each non-fatal finding of an importer (skipped materials, ...); may be empty.
  std::function<void(const std::string&)> warning;
  // Resolves a scene object's "data:REL" path (docs/scenes.md); empty: $TSAH_DATA_DIR/REL.
  std::function<std::string(const std::string& rel)> resolveDataPath;
};

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
// Throws anim::ImportError naming the file and the problem.
Animation load(const std::string& input, const LoadOptions& options = {});

}  // namespace anim
