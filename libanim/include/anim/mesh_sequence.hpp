#pragma once
// Frame sequences of mesh files (any format OpenMesh reads): resolving a printf pattern, a glob, a
// directory or a JSON manifest into an ordered file list, reading each mesh, and checking that every
// frame has the topology of the first.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/load_options.hpp"

namespace anim {

// One mesh file: triangulated faces (polygons fanned into triangles) and vertex positions.
struct MeshFrame {
  std::vector<uint32_t> indices;  // 3 per triangle
  std::vector<float> positions;   // 3 per vertex
  uint32_t faceCount = 0;         // faces in the file before triangulation
  uint32_t polygonsTriangulated = 0;
};

// Reads one mesh file (OBJ, PLY, OFF, STL, OM). Throws tsah::FileError naming the file.
MeshFrame readMesh(const std::string& path);
// Parses OBJ text held in memory (`file` names it in messages); readMesh uses it for .obj files.
MeshFrame decodeObj(std::span<const uint8_t> bytes, const std::string& file);

struct FrameList {
  std::vector<std::string> files;
  std::vector<double> times;  // empty, or one time per file (manifest)
};

// Orders names so that embedded numbers compare by value: walk_9 < walk_10.
bool naturalLess(const std::string& a, const std::string& b);

// The files named by a printf pattern (frames/walk_%04d.obj: every existing number from the first
// found), a glob ('frames/*.obj') or a directory (every mesh file in it), in natural order.
FrameList listFrames(const std::string& spec);

// A JSON manifest: {"frames": ["a.obj", {"file": "b.obj", "time": 0.5}, ...]} or a bare array;
// paths are relative to the manifest. Times, when given, must be given for every frame.
FrameList readManifest(const std::string& path);
// The same for a manifest's bytes already in memory (`path` names it and anchors relative files).
FrameList decodeManifest(std::span<const uint8_t> bytes, const std::string& path);

// Reads every file, checks topology against the first file and builds the animation (times
// 0, 1, 2, ... unless the list carries times).
Animation importSequence(const FrameList& frames, const LoadOptions& options, std::string name);

// True when the extension is one OpenMesh reads (.obj .ply .off .stl .om, any case).
bool isMeshFile(const std::string& path);

}  // namespace anim
