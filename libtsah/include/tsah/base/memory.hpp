#pragma once
// How much memory this machine can give a new allocation, and the check that refuses work that
// would not fit before any of it is allocated (with overcommit a huge vector would "succeed" and
// the process be killed later while filling it).
#include <cstddef>
#include <cstdint>
#include <string>

namespace tsah {

// MemAvailable of /proc/meminfo (memory obtainable without swapping), or the physical memory
// where that is not readable; at most $TSAH_MEMORY_LIMIT_MB MiB when that is set (a container's
// share, or the fuzzers' budget). requireMemory below is capped the same way.
std::size_t availableMemoryBytes();

// Throws tsah::Failure "WHO: WHAT would need N MiB, more than the M MiB available" when bytes exceed
// availableMemoryBytes().
void checkFitsInMemory(std::size_t bytes, const std::string& who, const std::string& what);

// The same check before one allocation, counting free swap too: throws tsah::Failure
// "WHO: WHAT needs N MiB, but only M MiB of memory are available".
void requireMemory(uint64_t bytes, const std::string& who, const std::string& what);

}  // namespace tsah
