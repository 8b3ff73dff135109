#pragma once
// Helpers shared by the test executables.
#include <filesystem>
#include <string>

namespace tsah::test {

// The real-data folder (../shared/data by default, TSAH_DATA_DIR in the environment overrides).
std::filesystem::path dataDir();

// Unpacks data/<relative archive> (a .tar.xz) once into the build tree and returns the folder it
// made; empty when the data folder or archive is absent (the caller then GTEST_SKIPs).
std::filesystem::path unpackedData(const std::string& archive, const std::string& folder);

// A fresh empty directory under the system temp dir, unique to the running test.
std::filesystem::path scratchDir();

}  // namespace tsah::test
