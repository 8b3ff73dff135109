#pragma once
// Pinhole cameras for the runtimes: a look-at description, automatic framing of an animation's
// bounds and primary ray generation (device-safe; an animation's camera path: camera_path.hpp).
#include <span>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/sampling.hpp"

namespace tsah {

struct Camera {
  Vec3 eye{0, 0, 5};
  Vec3 lookAt{0, 0, 0};
  Vec3 up{0, 1, 0};
  float fovYDegrees = 45.0f;  // vertical field of view
};

// Throws tsah::ConfigError when eye == lookAt, up is parallel to the view direction, or the field of
// view is outside (0, 180) degrees.
void validateCamera(const Camera& camera);

// A camera that sees the whole box (typically the animation's bounds over all frames) with the
// given vertical field of view and image aspect (width / height): it looks at the box centre from
// a three-quarter view above the side where the box is thinnest, so a walking figure is seen from
// its side. `up` is the scene's up direction (normalized here).
Camera fitCamera(const Aabb& bounds, Vec3 up = {0, 1, 0}, float fovYDegrees = 45.0f, float aspect = 4.0f / 3.0f);

// Precomputed ray generation for one image size.
struct CameraRays {
  Vec3 eye;
  Vec3 corner;  // direction through the top-left image corner
  Vec3 dx, dy;  // direction change per pixel to the right / down

  // Ray through image position (px, py), in pixels from the top-left corner (pixel x's centre is x + 0.5).
  TSAH_HD Ray ray(float px, float py) const {
    Ray r;
    r.org = eye;
    r.dir = normalize(corner + dx * px + dy * py);
    r.tmin = 0.0f;
    r.tmax = 3.402823466e38f;
    return r;
  }
};

CameraRays cameraRays(const Camera& camera, uint32_t width, uint32_t height);

}  // namespace tsah
