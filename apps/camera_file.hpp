#pragma once
// Camera files of `tsah trace --camera`: {"eye": [x,y,z], "look_at": [x,y,z], "up": [x,y,z],
// "fov": degrees} for a fixed camera, or {"keys": [{"time": t, ...}, ...]} for a path.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"

namespace tsah::cli {

// Reads and checks a camera file; throws tsah::FileError naming the file and the problem.
std::vector<anim::CameraKey> loadCameraFile(const std::string& path);
// The same for the file's bytes already in memory (`path` names it in messages).
std::vector<anim::CameraKey> decodeCameraFile(std::span<const uint8_t> bytes, const std::string& path);

}  // namespace tsah::cli
