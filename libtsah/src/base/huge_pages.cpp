#include "tsah/base/huge_pages.hpp"

#include <algorithm>
#include <cstdlib>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tsah {

namespace {

bool huge(std::size_t bytes) { return bytes >= kHugePageBytes; }

std::size_t roundedUp(std::size_t bytes) { return (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes; }

}  // namespace

void* allocateTraversalMemory(std::size_t bytes, std::size_t alignment) {
  if (!huge(bytes)) return ::operator new(std::max<std::size_t>(bytes, 1), std::align_val_t(alignment));
  if (bytes > std::size_t(-1) - kHugePageBytes) throw std::bad_alloc();
  const std::size_t whole = roundedUp(bytes);
  void* memory = std::aligned_alloc(std::max(alignment, kHugePageBytes), whole);
  if (memory == nullptr) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  madvise(memory, whole, MADV_HUGEPAGE);  // a hint: refused where huge pages are off
#endif
  return memory;
}

void freeTraversalMemory(void* memory, std::size_t bytes, std::size_t alignment) noexcept {
  if (memory == nullptr) return;
  if (!huge(bytes))
    ::operator delete(memory, std::align_val_t(alignment));
  else
    std::free(memory);
}

}  // namespace tsah
