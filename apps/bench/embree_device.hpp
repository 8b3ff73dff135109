#pragma once
// An Embree 3 device that keeps the first error Embree reports, shared by the bench's Embree peers
// (embree_peer.cpp, embree_motion.cpp). Compiled only with Embree (TSAH_HAVE_EMBREE).
#include <embree3/rtcore.h>

#include <mutex>
#include <string>

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

}  // namespace tsah::bench
