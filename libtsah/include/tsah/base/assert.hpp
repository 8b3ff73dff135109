#pragma once
// Internal invariants: conditions that hold whatever the caller passes, so a failure is a bug in the
// toolkit, never a mistake of the caller (those are exceptions, tsah/base/error.hpp).
//
//   TSAH_ASSERT(cond, message)   without NDEBUG (Debug builds, the debug-asan preset): when cond is
//                                false, prints "tsah: internal error: FILE:LINE: message (cond)" on
//                                stderr and aborts. With NDEBUG (release builds) it compiles to
//                                nothing: neither cond nor message is evaluated.
//   TSAH_ASSERT_VALID(problem, what)
//                                for the validators that return std::optional<std::string> (validate,
//                                validateWide, ...): when `problem` holds a text, aborts as above with
//                                the message "what: text". Neither is evaluated with NDEBUG, so a
//                                full validation costs release builds nothing.
//
// message is anything std::string can be built from (a literal, a std::string, a concatenation).
// Never use these for input validation: release builds do not check them.
#include <cstdio>
#include <cstdlib>
#include <string>

namespace tsah::detail {

// Prints the internal-error line and aborts.
[[noreturn]] inline void assertionFailed(const char* file, int line, const std::string& message,
                                         const char* condition) {
  std::fprintf(stderr, "tsah: internal error: %s:%d: %s (%s)\n", file, line, message.c_str(), condition);
  std::fflush(stderr);
  std::abort();
}

}  // namespace tsah::detail

#ifdef NDEBUG
#define TSAH_ASSERT(cond, message) static_cast<void>(0)
#define TSAH_ASSERT_VALID(problem, what) static_cast<void>(0)
#else
#define TSAH_ASSERT(cond, message)                                                      \
  do {                                                                                  \
    if (!(cond)) ::tsah::detail::assertionFailed(__FILE__, __LINE__, (message), #cond); \
  } while (false)
#define TSAH_ASSERT_VALID(problem, what)                                                                   \
  do {                                                                                                     \
    if (const auto tsahAssertProblem_ = (problem))                                                         \
      ::tsah::detail::assertionFailed(__FILE__, __LINE__, std::string(what) + ": " + *tsahAssertProblem_, \
                                      #problem);                                                           \
  } while (false)
#endif
