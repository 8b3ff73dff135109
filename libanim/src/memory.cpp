#include "anim/memory.hpp"

#include <fstream>
#include <sstream>
#include <unistd.h>

#include "anim/error.hpp"

namespace anim {

std::size_t availableMemoryBytes() {
  std::ifstream meminfo("/proc/meminfo");
  std::string line;
  while (std::getline(meminfo, line)) {
    std::istringstream fields(line);
    std::string key;
    std::size_t kib = 0;
    if (fields >> key >> kib && key == "MemAvailable:") return kib * 1024;
  }
  const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && pageSize > 0 ? std::size_t(pages) * std::size_t(pageSize) : std::size_t(1) << 60;
}

void checkFitsInMemory(std::size_t bytes, const std::string& who, const std::string& what) {
  const std::size_t available = availableMemoryBytes();
  if (bytes > available)
    throw Error(who + ": " + what + " would need " + std::to_string(bytes >> 20) + " MiB, more than the " +
                std::to_string(available >> 20) + " MiB of memory available");
}

}  // namespace anim
