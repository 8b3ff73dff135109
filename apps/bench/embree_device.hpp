#pragma once
// An Embree 3 device that keeps the first error Embree reports, shared by the bench's Embree peers
// (embree_peer.cpp, embree_motion.cpp), and the ray queries both trace with. Compiled only with
// Embree (TSAH_HAVE_EMBREE).
#include <embree3/rtcore.h>

#include <mutex>
#include <string>

#include "bench/ray_batch.hpp"

namespace tsah::bench {

class EmbreeDevice {
 public:
  // threads: Embree's worker threads (0: all cores). Throws tsah::Failure when Embree cannot
  // create the device.
  explicit EmbreeDevice(unsigned threads);
  ~EmbreeDevice();
  EmbreeDevice(const EmbreeDevice&) = delete;
  EmbreeDevice& operator=(const EmbreeDevice&) = delete;

  RTCDevice get() const { return device_; }
  // Throws tsah::Failure("Embree: WHAT failed: FIRST ERROR") when the device reports an error.
  void check(const char* what);

 private:
  RTCDevice device_ = nullptr;
  std::mutex mutex_;
  std::string error_;  // the first error Embree reported
};

// One ray in Embree's form at Embree time `time`, and the two queries both peers trace with.
RTCRay embreeRay(const Ray& ray, float time);
Hit embreeClosest(RTCScene scene, const Ray& ray, float time);  // triangle (kNoHit: a miss), t, u, v
bool embreeOccluded(RTCScene scene, const Ray& ray, float time);

}  // namespace tsah::bench
