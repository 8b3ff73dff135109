#pragma once
// Storage for the arrays a traversal reads at random: wide nodes and triangle packets. A ray
// through a large tree touches a new page at almost every node, and with 4 KiB pages the
// translation lookaside buffer covers a few MiB: the walks to the page tables add to an incoherent
// ray's every step (docs/wide-bvh.md gives the measured gain). Large arrays therefore ask the
// kernel for transparent huge pages (2 MiB): they are allocated 2 MiB-aligned, rounded up to whole
// 2 MiB pages, and advised with madvise(MADV_HUGEPAGE) before their first touch, so that the pages
// are huge from the first fault on machines whose transparent huge pages are set to "madvise" (as
// on the bench's GPU host and the development VM). Only a hint: where the kernel gives small pages
// the arrays work the same. Smaller arrays are ordinary aligned allocations.
#include <cstddef>
#include <new>
#include <vector>

namespace tsah {

// Arrays of at least this many bytes go to huge pages (at most half of such an array is rounding).
inline constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;

// bytes of memory aligned to `alignment` (a power of two), advised to huge pages when bytes is at
// least kHugePageBytes. Throws std::bad_alloc when none is left.
void* allocateTraversalMemory(std::size_t bytes, std::size_t alignment);
// Frees what allocateTraversalMemory returned for the same bytes and alignment.
void freeTraversalMemory(void* memory, std::size_t bytes, std::size_t alignment) noexcept;

template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) {}
  T* allocate(std::size_t n) {
    if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
    return static_cast<T*>(allocateTraversalMemory(n * sizeof(T), alignof(T)));
  }
  void deallocate(T* p, std::size_t n) noexcept { freeTraversalMemory(p, n * sizeof(T), alignof(T)); }
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const {
    return true;
  }
};

// A vector whose storage is allocateTraversalMemory's.
template <class T>
using TraversalVector = std::vector<T, HugePageAllocator<T>>;

}  // namespace tsah
