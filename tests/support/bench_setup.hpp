#pragma once
// The runtime bench's setup on a small image for the bench tests: frames at the given times, a
// camera fitted to the whole animation, 2 shadow rays per pixel, 2 threads.
#include <cstdint>
#include <utility>
#include <vector>

#include "bench/runtime_bench.hpp"
#include "tsah/render/camera.hpp"
#include "test_support.hpp"

namespace tsah::test {

inline tsah::bench::RuntimeSetup smallBenchSetup(const anim::Animation& a, std::vector<double> times, uint32_t width,
                                                  uint32_t height, uint32_t aoSamples) {
  tsah::bench::RuntimeSetup setup;
  setup.times = std::move(times);
  const tsah::Aabb bounds = tsah::test::boxOf(a.bounds());
  const tsah::Camera camera = tsah::fitCamera(bounds, {0, 1, 0}, 45.0f, float(width) / float(height));
  setup.camera = [camera](double) { return camera; };
  setup.lighting = tsah::fitLighting(bounds, camera, {0, 1, 0}, 0.1f, false);
  setup.settings.width = width;
  setup.settings.height = height;
  setup.settings.aoSamples = aoSamples;
  setup.settings.shadowSamples = 2;
  setup.threads = 2;
  return setup;
}

}  // namespace tsah::test
