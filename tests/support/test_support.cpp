#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
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

}  // namespace tsah::test
