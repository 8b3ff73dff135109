#pragma once
// Writes an animation as an OBJ frame sequence (one file per keyframe, same faces in every file),
// the form most users' tools exchange.
#include <string>

#include "anim/animation.hpp"

namespace tsah {
class AtomicFileSet;
}

namespace anim {

// `pattern` holds one printf number, e.g. "out/wave_%04d.obj"; frames are numbered from 1.
// The files appear together or not at all (tsah::AtomicFileSet). Returns the number of files written.
std::size_t saveObjSequence(const Animation& animation, const std::string& pattern);

// One keyframe as one OBJ file (vertices in the animation's order, then the faces), written
// atomically: the topology file that goes with a point cache.
void saveObjFrame(const Animation& animation, uint32_t keyframe, const std::string& path);
// The same as one file of an output set (a point cache's topology goes with the cache).
void saveObjFrame(const Animation& animation, uint32_t keyframe, const std::string& path, tsah::AtomicFileSet& set);

}  // namespace anim
