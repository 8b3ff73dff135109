#pragma once
// An animation's camera path (anim::CameraKey, from BART scenes and scene files) as cameras: kept
// apart from camera.hpp so that device code sees no animation model.
#include <span>

#include "anim/animation.hpp"
#include "tsah/render/camera.hpp"

namespace tsah {

// The camera of the path at time t: linear interpolation of the keys, clamped at the ends. Throws
// tsah::ConfigError when the path is empty.
Camera cameraAt(std::span<const anim::CameraKey> path, double t);

}  // namespace tsah
