#pragma once
// Independent tasks on the caller's TBB arena (all cores, or what a tbb::global_control allows).
// Errors do not depend on scheduling: every task runs, then the lowest failing task's exception is
// rethrown. Include it from sources only (the caller links TBB).
#include <tbb/parallel_for.h>

#include <cstddef>
#include <exception>
#include <vector>

namespace tsah {

// Runs body(i) for every i in [0, count), concurrently, one task per index.
template <typename Body>
void forEachConcurrently(std::size_t count, Body&& body) {
  std::vector<std::exception_ptr> errors(count);
  tbb::parallel_for(std::size_t(0), count, std::size_t(1), [&](std::size_t i) {
    try {
      body(i);
    } catch (...) {
      errors[i] = std::current_exception();
    }
  });
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace tsah
