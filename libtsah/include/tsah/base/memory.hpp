#pragma once
// How much memory this machine can give a new allocation, and the check that refuses work that
// would not fit before any of it is allocated (with overcommit a huge vector would "succeed" and
// the process be killed later while filling it).
//
// Headroom: a request is measured against a budget, not against all that is free. The budget is
// kMemoryBudgetFraction (3/4) of MemAvailable, so the page cache, the other processes and the
// estimates' own error keep a quarter; and at most $TSAH_MEMORY_LIMIT_MB MiB when that is set (a
// container's share, or the fuzzers' budget). The command line and the Python module call the
// same checks, so they refuse the same requests.
#include <cstddef>
#include <cstdint>
#include <string>

namespace tsah {

// The share of MemAvailable one request may take.
inline constexpr double kMemoryBudgetFraction = 0.75;

// The budget: kMemoryBudgetFraction of MemAvailable of /proc/meminfo (memory obtainable without
// swapping), or of the physical memory where that is not readable; at most $TSAH_MEMORY_LIMIT_MB MiB.
std::size_t availableMemoryBytes();

// Throws tsah::Failure "WHO: WHAT would need N MiB, more than the M MiB of memory available (...)"
// when bytes exceed availableMemoryBytes(); the parenthesis says where M comes from.
void checkFitsInMemory(std::size_t bytes, const std::string& who, const std::string& what);

// The same check before one allocation, counting free swap too (the budget is the fraction of
// MemAvailable + SwapFree): throws tsah::Failure "WHO: WHAT needs N MiB, but only M MiB of memory
// are available (...)".
void requireMemory(uint64_t bytes, const std::string& who, const std::string& what);

}  // namespace tsah
