#pragma once
// The GPU two-level tests' fixture (include only where TSAH_HAVE_CUDA): skipped without a device,
// the test scene of two_level_scene.hpp written to the test's scratch folder and built with the
// small tree options.
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>

#include "cuda_test_support.hpp"
#include "tsah/scene/two_level.hpp"
#include "two_level_scene.hpp"

namespace tsah::test {

class GpuTwoLevelSceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_GPU();
    dir = scratchDir();
    scene = std::make_unique<TwoLevelScene>(
        loadTwoLevelScene(writeTwoLevelScene(dir).string(), {}, smallTwoLevelOptions()));
  }
  std::filesystem::path dir;
  std::unique_ptr<TwoLevelScene> scene;
};

}  // namespace tsah::test
