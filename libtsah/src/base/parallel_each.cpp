#include "tsah/base/parallel_each.hpp"

#include <tbb/parallel_for.h>

#include <exception>
#include <vector>

namespace tsah {

void forEachConcurrently(std::size_t count, const std::function<void(std::size_t)>& body) {
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
