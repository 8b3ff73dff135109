#pragma once
// Animated models baked into keyframes: glTF 2.0 (.gltf/.glb), FBX, Collada (.dae) through Assimp,
// and Quake II MD2 through a reader of our own (Assimp's MD2 loader keeps one frame only).
//
// Every mesh of the scene is placed in world space and merged into one triangle topology. Per
// keyframe: node transforms from the clip's channels (linear translation and scale, slerp rotation),
// morph-target weights from its morph channels, then linear blend skinning with the bones' inverse
// bind matrices. Vertices that coincide in every keyframe are welded. Details: docs/importers.md.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/load_options.hpp"

namespace anim {

// True for the extensions importModel handles: .md2 .gltf .glb .fbx .dae (any case).
bool isModelFile(const std::string& path);

// Loads an animated model. Uses options.fps (0: the clip's own key times; MD2: 10 keyframes per
// second), options.clip (a clip name or index; empty: the first clip, MD2: every frame), and reports
// through options.warning / options.progress. Throws tsah::FileError naming the file.
Animation importModel(const std::string& path, const LoadOptions& options = {});

// The names of the clips a model holds (MD2: its frame groups, "stand", "run", ...).
std::vector<std::string> modelClips(const std::string& path);

// MD2 from memory: every keyframe (or one frame group chosen by options.clip), one keyframe every
// 1/fps seconds (10 per second when options.fps is 0). Coordinates stay in the file's frame (z up).
// Every offset and count is checked against the data; bad input throws tsah::FileError naming `file`.
Animation decodeMd2(std::span<const uint8_t> bytes, const std::string& file, const LoadOptions& options = {});
std::vector<std::string> md2Clips(std::span<const uint8_t> bytes, const std::string& file);

}  // namespace anim
