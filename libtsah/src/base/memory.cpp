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

std::size_t physicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && pageSize > 0 ? std::size_t(pages) * std::size_t(pageSize) : std::size_t(1) << 60;
}

std::string mib(uint64_t bytes) { return std::to_string(bytes >> 20); }

// A request's budget out of `free` bytes, and the words that say how it was chosen.
struct Budget {
  uint64_t bytes = 0;
  std::string why;
};
Budget budgetOf(uint64_t free, const char* freeWhat) {
  const uint64_t share = uint64_t(double(free) * kMemoryBudgetFraction);
  const std::size_t limit = memoryLimitBytes();
  if (limit && limit < share) return {limit, "TSAH_MEMORY_LIMIT_MB"};
  return {share, std::to_string(int(kMemoryBudgetFraction * 100)) + "% of the " + mib(free) + " MiB " + freeWhat};
}

Budget memoryBudget() {
  const std::size_t available = meminfoBytes("MemAvailable:");
  return available ? budgetOf(available, "free") : budgetOf(physicalMemoryBytes(), "of the machine");
}

}  // namespace

std::size_t availableMemoryBytes() { return std::size_t(memoryBudget().bytes); }

void requireMemory(uint64_t bytes, const std::string& who, const std::string& what) {
  // MemAvailable + free swap is what one allocation can still get now.
  const std::size_t memory = meminfoBytes("MemAvailable:");
  const Budget budget = memory ? budgetOf(memory + meminfoBytes("SwapFree:"), "free with swap")
                               : budgetOf(physicalMemoryBytes(), "of the machine");
  if (bytes > budget.bytes)
    throw Failure(who + ": " + what + " needs " + mib(bytes + (1u << 20) - 1) + " MiB, but only " + mib(budget.bytes) +
                  " MiB of memory are available (" + budget.why + ")");
}

void checkFitsInMemory(std::size_t bytes, const std::string& who, const std::string& what) {
  const Budget budget = memoryBudget();
  if (bytes > budget.bytes)
    throw Failure(who + ": " + what + " would need " + mib(bytes) + " MiB, more than the " + mib(budget.bytes) +
                  " MiB of memory available (" + budget.why + ")");
}

}  // namespace tsah
