// What the bench reports about Embree; the peer itself is embree_peer.cpp (built only with Embree).
#include "bench/embree_peer.hpp"

#if TSAH_HAVE_EMBREE
#include <embree3/rtcore_config.h>
#endif

namespace tsah::bench {

bool embreeAvailable() {
#if TSAH_HAVE_EMBREE
  return true;
#else
  return false;
#endif
}

std::string embreeStatus() {
#if TSAH_HAVE_EMBREE
  return RTC_VERSION_STRING;
#else
  return "Embree is missing: this tsah was built without Embree 3 (install libembree-dev and reconfigure)";
#endif
}

}  // namespace tsah::bench
