// TSAH_ASSERT / TSAH_ASSERT_VALID (tsah/base/assert.hpp): abort with one "tsah: internal error" line in
// builds without NDEBUG, nothing at all (not even the condition) with NDEBUG; and the error classes
// of tsah/base/error.hpp.
#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <type_traits>

#include "tsah/base/assert.hpp"
#include "tsah/base/error.hpp"

namespace {

TEST(Assert, TrueConditionsPass) {
  int evaluated = 0;
  TSAH_ASSERT((++evaluated, true), "never printed");
  TSAH_ASSERT_VALID((++evaluated, std::optional<std::string>{}), "never printed");
#ifdef NDEBUG
  EXPECT_EQ(evaluated, 0);
#else
  EXPECT_EQ(evaluated, 2);
#endif
}

#ifndef NDEBUG

TEST(AssertDeathTest, FailingAssertionAbortsWithTheInternalErrorLine) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(TSAH_ASSERT(1 + 1 == 3, "arithmetic is broken"),
               "tsah: internal error: .*test_assert\\.cpp:[0-9]+: arithmetic is broken \\(1 \\+ 1 == 3\\)");
  const std::string node = "node 7";
  EXPECT_DEATH(TSAH_ASSERT(false, node + " lost its parent"), "internal error: .*: node 7 lost its parent \\(false\\)");
}

TEST(AssertDeathTest, FailingValidationAbortsWithTheValidatorsText) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto broken = [] { return std::optional<std::string>("root has a parent"); };
  EXPECT_DEATH(TSAH_ASSERT_VALID(broken(), "after round 3"),
               "tsah: internal error: .*test_assert\\.cpp:[0-9]+: after round 3: root has a parent \\(broken\\(\\)\\)");
}

#else

TEST(Assert, ReleaseBuildsEvaluateNothing) {
  // With NDEBUG the condition and the message are not evaluated: no side effect, no abort.
  int conditionRuns = 0, messageRuns = 0;
  [[maybe_unused]] const auto condition = [&] {
    ++conditionRuns;
    return false;
  };
  [[maybe_unused]] const auto message = [&] {
    ++messageRuns;
    return std::string("never built");
  };
  TSAH_ASSERT(condition(), message());
  TSAH_ASSERT_VALID((++conditionRuns, std::optional<std::string>("broken")), message());
  EXPECT_EQ(conditionRuns, 0);
  EXPECT_EQ(messageRuns, 0);
}

#endif

// Which class answers for whose mistake: one base, FileError a DataError, none a std::invalid_argument.
TEST(Errors, OneBaseForEveryKindOfMistake) {
  static_assert(std::is_base_of_v<tsah::Error, tsah::ConfigError>);
  static_assert(std::is_base_of_v<tsah::Error, tsah::DataError>);
  static_assert(std::is_base_of_v<tsah::DataError, tsah::FileError>);
  static_assert(std::is_base_of_v<tsah::Error, tsah::Failure>);
  static_assert(std::is_base_of_v<std::runtime_error, tsah::Error>);
  static_assert(!std::is_base_of_v<tsah::ConfigError, tsah::DataError>);
  static_assert(!std::is_base_of_v<tsah::Failure, tsah::FileError>);
  const tsah::FileError e("scene.obj", "line 4: face references vertex 9");
  EXPECT_STREQ(e.what(), "scene.obj: line 4: face references vertex 9");
  EXPECT_EQ(e.file(), "scene.obj");
  EXPECT_THROW(throw tsah::FileError("a.tbvh", "bad"), tsah::DataError);
}

}  // namespace
