#pragma once
// Point caches from VFX tools: PC2 (Blender, 3ds Max, Maya plug-ins) and MDD (LightWave, Blender,
// Houdini). A cache holds only positions, one block of xyz floats per point per frame; the triangles
// come from a mesh file with the same point order. Byte layouts and time rules: docs/point-caches.md.
//
//   PC2 (little-endian): "POINTCACHE2\0", int32 version (1), int32 points, float start frame,
//                        float sample rate (frames between samples), int32 samples, then the floats.
//                        Sample i lies at time start + i * rate (in frames).
//   MDD (big-endian):    int32 frames, int32 points, float time[frames] (seconds), then the floats.
//                        Blender's exporter writes one extra block (the rest pose) before the
//                        frames; it is recognised by the file size and skipped.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/load_options.hpp"

namespace tsah {
class AtomicFileSet;
}

namespace anim {

enum class PointCacheFormat { Pc2, Mdd };

// The format of a file named *.pc2 or *.mdd (any case); nothing for other names.
std::optional<PointCacheFormat> pointCacheFormat(const std::string& path);

// What a cache file holds, decoded and validated.
struct PointCache {
  uint32_t pointCount = 0;
  std::vector<double> times;     // one per frame, strictly increasing
  std::vector<float> positions;  // times.size() blocks of pointCount * 3 floats
  bool skippedRestFrame = false; // MDD: an extra leading block (Blender's rest pose) was skipped
};

// Decoders: every count is checked against the byte size before anything is allocated; a wrong
// signature, a truncated or oversized file, an absurd count, a non-finite or non-increasing time or
// a NaN/Inf coordinate throws tsah::FileError naming `file`.
PointCache decodePc2(std::span<const uint8_t> bytes, const std::string& file);
PointCache decodeMdd(std::span<const uint8_t> bytes, const std::string& file);
PointCache decodePointCache(std::span<const uint8_t> bytes, const std::string& file, PointCacheFormat format);

// Encoders of an animation's keyframes. PC2 can only express uniformly spaced samples: keyframe
// times that are not (within 1e-4 of a step) throw tsah::DataError suggesting `--frames N`. MDD stores
// the times as they are (as float32).
std::vector<uint8_t> encodePc2(const Animation& animation);
std::vector<uint8_t> encodeMdd(const Animation& animation);

// Writes the cache in the format of the path's extension, atomically (temporary file + rename),
// or as one file of an output set (with its topology OBJ: tsah/base/files.hpp).
void savePointCache(const Animation& animation, const std::string& path);
void savePointCache(const Animation& animation, const std::string& path, tsah::AtomicFileSet& set);

// A mesh (topology) and a cache (positions) to be loaded together.
struct PointCacheInput {
  std::string mesh;
  std::string cache;
};

// "mesh.obj+cache.pc2" (or +cache.mdd): the pair, split at the last '+' whose right side names a
// cache file; nothing for any other input.
std::optional<PointCacheInput> splitPointCacheInput(const std::string& input);

// A JSON manifest object {"mesh": "horse.obj", "cache": "horse.mdd"} (paths relative to the
// manifest): the pair; nothing when the manifest is not of this form (e.g. a frame list). Throws
// tsah::FileError when it names a cache but is malformed.
std::optional<PointCacheInput> readPointCacheManifest(const std::string& path);

// Reads the mesh (only its faces and point count are used; its positions are ignored) and the cache,
// checks that the point counts agree, and builds the animation with the cache's times. Warnings
// (a skipped MDD rest frame) go to options.warning. Throws tsah::FileError naming the file at fault.
Animation importPointCache(const PointCacheInput& input, const LoadOptions& options = {});

}  // namespace anim
