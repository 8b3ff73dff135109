#include "tsah/base/memory.hpp"

#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <unistd.h>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

// The bytes of one /proc/meminfo field (0 when absent or unreadable).
std::size_t meminfoBytes(const std::string& field) {
  std::ifstream meminfo("/proc/meminfo");
  std::string line;
  while (std::getline(meminfo, line)) {
    std::istringstream fields(line);
    std::string key;
    std::size_t kib = 0;
    if (fields >> key >> kib && key == field) return kib * 1024;
  }
  return 0;
}

// $TSAH_MEMORY_LIMIT_MB, when it is a positive whole number: a cap on what is reported available
// (a container's share of the machine, or a fuzzer's budget); 0 when unset or not a number.
std::size_t memoryLimitBytes() {
  const char* text = std::getenv("TSAH_MEMORY_LIMIT_MB");
  if (!text || !*text) return 0;
  char* end = nullptr;
  const unsigned long long mib = std::strtoull(text, &end, 10);
  if (*end != '\0' || mib == 0 || mib > (std::numeric_limits<std::size_t>::max() >> 20)) return 0;
  return std::size_t(mib) << 20;
}

std::size_t capped(std::size_t bytes) {
  const std::size_t limit = memoryLimitBytes();
  return limit && limit < bytes ? limit : bytes;
}

std::size_t physicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && pageSize > 0 ? std::size_t(pages) * std::size_t(pageSize) : std::size_t(1) << 60;
}

}  // namespace

std::size_t availableMemoryBytes() {
  const std::size_t available = meminfoBytes("MemAvailable:");
  return capped(available ? available : physicalMemoryBytes());
}

void requireMemory(uint64_t bytes, const std::string& who, const std::string& what) {
  // MemAvailable + free swap is what one allocation can still get now.
  const std::size_t memory = meminfoBytes("MemAvailable:");
  const uint64_t available = capped(memory ? memory + meminfoBytes("SwapFree:") : physicalMemoryBytes());
  if (bytes > available)
    throw Failure(who + ": " + what + " needs " + std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB, but only " +
                std::to_string(available >> 20) + " MiB of memory are available");
}

void checkFitsInMemory(std::size_t bytes, const std::string& who, const std::string& what) {
  const std::size_t available = availableMemoryBytes();
  if (bytes > available)
    throw Failure(who + ": " + what + " would need " + std::to_string(bytes >> 20) + " MiB, more than the " +
                std::to_string(available >> 20) + " MiB of memory available");
}

}  // namespace tsah
