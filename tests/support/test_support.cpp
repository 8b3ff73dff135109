#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <random>
#include <unistd.h>

namespace tsah::test {

std::filesystem::path dataDir() {
  if (const char* env = std::getenv("TSAH_DATA_DIR")) return env;
  return TSAH_DATA_DIR;
}

std::filesystem::path unpackedData(const std::string& archive, const std::string& folder) {
  namespace fs = std::filesystem;
  const fs::path source = dataDir() / archive;
  if (!fs::exists(source)) return {};
  const fs::path cache = fs::temp_directory_path() / ("tsah-test-data-" + std::to_string(::getuid()));
  const fs::path out = cache / folder;
  if (fs::exists(out / ".complete")) return out;
  // Unpack into a private folder and rename it into place, so parallel tests never see half a tree.
  const fs::path staging = cache / ("staging-" + std::to_string(::getpid()));
  fs::remove_all(staging);
  fs::create_directories(staging);
  const std::string cmd = "tar -xJf '" + source.string() + "' -C '" + staging.string() + "'";
  if (std::system(cmd.c_str()) != 0 || !fs::exists(staging / folder)) return {};
  if (std::FILE* marker = std::fopen((staging / folder / ".complete").c_str(), "w")) std::fclose(marker);
  std::error_code ec;
  fs::rename(staging / folder, out, ec);  // fails harmlessly when another test won the race
  fs::remove_all(staging, ec);
  if (!fs::exists(out / ".complete")) return {};
  return out;
}

std::filesystem::path scratchDir() {
  namespace fs = std::filesystem;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "tsah";
  for (char& c : name)
    if (c == '/') c = '_';
  const fs::path dir = fs::temp_directory_path() /
                       ("tsah-" + std::to_string(::getpid()) + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

MovingTriangles randomMovingTriangles(uint32_t triangles, uint32_t frames, uint32_t seed, float maxSpeed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-20.0f, 20.0f), small(-1.0f, 1.0f), vel(-maxSpeed, maxSpeed);
  MovingTriangles s;
  s.frames = frames;
  const uint32_t vertices = triangles * 3;
  for (uint32_t i = 0; i < vertices; ++i) s.indices.push_back(i);
  s.positions.resize(std::size_t(frames) * vertices * 3);
  for (uint32_t t = 0; t < triangles; ++t) {
    const float c[3] = {pos(rng), pos(rng), pos(rng)};
    const float v[3] = {vel(rng), vel(rng), vel(rng)};
    for (uint32_t corner = 0; corner < 3; ++corner) {
      const float o[3] = {small(rng), small(rng), small(rng)};
      for (uint32_t f = 0; f < frames; ++f)
        for (int a = 0; a < 3; ++a)
          s.positions[(std::size_t(f) * vertices + t * 3 + corner) * 3 + a] = c[a] + o[a] + v[a] * float(f);
    }
  }
  return s;
}

}  // namespace tsah::test
