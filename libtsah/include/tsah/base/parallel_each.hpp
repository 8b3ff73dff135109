#pragma once
// Independent tasks on the caller's TBB arena (all cores, or what a tbb::global_control allows).
// Errors do not depend on scheduling: every task runs, then the lowest failing task's exception is
// rethrown.
#include <cstddef>
#include <functional>

namespace tsah {

// Runs body(i) for every i in [0, count), concurrently, one task per index.
void forEachConcurrently(std::size_t count, const std::function<void(std::size_t)>& body);

}  // namespace tsah
