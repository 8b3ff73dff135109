// Finding the bench's scenes in a data folder (bench/data_scan.hpp): sequences, BART scene files,
// single-file animations, archives unpacked into a cache (never into the data folder), skips.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <set>
#include <unistd.h>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "anim/obj_writer.hpp"
#include "anim/tanim.hpp"
#include "bench/data_scan.hpp"
#include "bench/process.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using tsah::bench::SceneSource;

using tsah::test::writeText;

// Every file below a folder with its size and modification time (to see that nothing changed).
std::set<std::string> listing(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    out.insert(e.path().string() + (e.is_regular_file() ? " " + std::to_string(e.file_size()) : "/") + " " +
               std::to_string(e.last_write_time().time_since_epoch().count()));
  return out;
}

const SceneSource* byName(const tsah::bench::DataScan& scan, const std::string& name) {
  for (const SceneSource& s : scan.scenes)
    if (s.name == name) return &s;
  return nullptr;
}

// A small data folder with one of everything the scanner handles.
struct DataFolder {
  fs::path root, data, cache;

  DataFolder() {
    root = tsah::test::scratchDir();
    data = root / "data";
    cache = root / "cache";
    const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 60, 3);
    // An OBJ sequence in a folder, and the same packed as .tar.xz in another folder.
    anim::saveObjSequence(wave, (data / "sequences" / "wave" / "f_%03d.obj").string());
    const fs::path staging = root / "pack";
    anim::saveObjSequence(wave, (staging / "packed-wave" / "%04d.obj").string());
    fs::create_directories(data / "archives");
    EXPECT_TRUE(tsah::bench::runProcess({"tar", "-cJf", (data / "archives" / "packed.tar.xz").string(), "-C",
                                         staging.string(), "packed-wave"})
                    .ok());
    // Single-file animations: a .tanim and an xz-compressed .tanim.
    fs::create_directories(data / "models");
    anim::saveTanim(wave, (data / "models" / "Wave-Model.tanim").string());
    anim::saveTanim(wave, (root / "squeezed.tanim").string());
    EXPECT_TRUE(tsah::bench::runProcess({"xz", "-zc", (root / "squeezed.tanim").string()},
                                        (data / "models" / "squeezed.tanim.xz").string())
                    .ok());
    // Static meshes, plain and compressed: skipped.
    writeText(data / "static" / "tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    writeText(root / "tri.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    EXPECT_TRUE(tsah::bench::runProcess({"xz", "-zc", (root / "tri.off").string()}, (data / "static" / "tri.off.xz").string()).ok());
    // BART: scene.aff (animation range, includes part.aff), broken.aff (includes a missing file),
    // part.aff (included: not a scene), still.aff (no animation range: not a scene), an editor backup.
    writeText(data / "bart" / "stage" / "scene.aff",
              "% a scene\na 0 2 5\nxs 1 1 1 0 0 1 0 0 0 0 {\ni 0 part.aff\n}\n");
    writeText(data / "bart" / "stage" / "part.aff", "p 3\n0 0 0\n1 0 0\n0 1 0\np 3\n0 0 1\n1 0 1\n0 1 1\n");
    writeText(data / "bart" / "stage" / "broken.aff", "a 0 1 3 # range\n{i 0 missing.aff}\n");
    writeText(data / "bart" / "stage" / "still.aff", "i 0 part.aff\n");
    writeText(data / "bart" / "stage" / "scene.aff~", "a 0 1 2\n");
    writeText(data / "README.md", "notes\n");
  }
};

TEST(BenchData, FindsEveryKindOfAnimationAndSkipsStaticMeshes) {
  DataFolder f;
  const std::set<std::string> before = listing(f.data);
  std::vector<std::string> messages;
  const tsah::bench::DataScan scan =
      tsah::bench::scanDataFolder(f.data, {f.cache, [&](const std::string& m) { messages.push_back(m); }});
  std::vector<std::string> names;
  for (const SceneSource& s : scan.scenes) names.push_back(s.name);
  EXPECT_EQ(names, (std::vector<std::string>{"packed-wave", "squeezed", "stage", "wave", "wave-model"}));

  EXPECT_EQ(byName(scan, "wave")->kind, "sequence");
  EXPECT_EQ(byName(scan, "wave")->origin, "sequences/wave");
  EXPECT_EQ(byName(scan, "packed-wave")->kind, "sequence");
  EXPECT_EQ(byName(scan, "packed-wave")->origin, "archives/packed.tar.xz");
  EXPECT_EQ(fs::path(byName(scan, "stage")->input).filename(), "scene.aff");
  EXPECT_EQ(byName(scan, "stage")->kind, "bart");
  EXPECT_EQ(byName(scan, "squeezed")->kind, "tanim");
  EXPECT_EQ(byName(scan, "squeezed")->origin, "models/squeezed.tanim.xz");
  EXPECT_EQ(byName(scan, "wave-model")->kind, "tanim");

  // Archives went to the cache, not next to the data; the data folder is untouched.
  for (const char* name : {"packed-wave", "squeezed"})
    EXPECT_EQ(byName(scan, name)->input.rfind(f.cache.string(), 0), 0u) << name;
  EXPECT_EQ(listing(f.data), before);
  EXPECT_EQ(messages.size(), 2u);  // one archive unpacked, one file decompressed
  // A second scan uses the cache: nothing is unpacked again, the same scenes are found.
  messages.clear();
  const tsah::bench::DataScan again =
      tsah::bench::scanDataFolder(f.data, {f.cache, [&](const std::string& m) { messages.push_back(m); }});
  EXPECT_TRUE(messages.empty());
  ASSERT_EQ(again.scenes.size(), scan.scenes.size());
  for (std::size_t i = 0; i < scan.scenes.size(); ++i) EXPECT_EQ(again.scenes[i].input, scan.scenes[i].input);

  std::vector<std::string> skipped;
  for (const auto& s : scan.skipped) skipped.push_back(s.path + ": " + s.reason);
  std::sort(skipped.begin(), skipped.end());
  EXPECT_EQ(skipped, (std::vector<std::string>{
                         "bart/stage/broken.aff: includes missing.aff, which is not in the folder",
                         "static/tri.obj: a single static mesh, not an animation",
                         "static/tri.off.xz: a single static mesh, not an animation"}));

  // Every scene found loads, as the bench will load it.
  for (const SceneSource& s : scan.scenes) {
    const anim::Animation a = anim::load(s.input);
    EXPECT_GT(a.triangleCount(), 0u) << s.name;
    EXPECT_GE(a.keyframeCount(), 2u) << s.name;
  }
}

TEST(BenchData, UnpacksOnceAndAgainWhenTheArchiveChanges) {
  DataFolder f;
  const fs::path archive = f.data / "archives" / "packed.tar.xz";
  const fs::path first = tsah::bench::unpackArchive(archive, f.cache);
  ASSERT_TRUE(fs::exists(first / "packed-wave" / "0001.obj"));
  ASSERT_TRUE(fs::exists(first / ".complete"));
  const auto stamp = fs::last_write_time(first / ".complete");
  // A second call reuses the unpacked copy.
  fs::remove(first / "packed-wave" / "0002.obj");
  EXPECT_EQ(tsah::bench::unpackArchive(archive, f.cache), first);
  EXPECT_FALSE(fs::exists(first / "packed-wave" / "0002.obj"));
  EXPECT_EQ(fs::last_write_time(first / ".complete"), stamp);
  // A changed archive (other size) gets its own fresh copy.
  { std::ofstream(f.root / "pack" / "packed-wave" / "extra.txt") << "more\n"; }
  ASSERT_TRUE(tsah::bench::runProcess({"tar", "-cJf", archive.string(), "-C", (f.root / "pack").string(), "packed-wave"}).ok());
  const fs::path second = tsah::bench::unpackArchive(archive, f.cache);
  EXPECT_NE(second, first);
  EXPECT_TRUE(fs::exists(second / "packed-wave" / "0002.obj"));
  // No staging folders are left behind.
  for (const auto& e : fs::directory_iterator(f.cache))
    EXPECT_EQ(e.path().filename().string().find(".staging"), std::string::npos) << e.path();
}

TEST(BenchData, DataPathsThatLeaveTheDataFolderAreRefused) {
  DataFolder f;
  auto refusal = [&](const std::string& rel) -> std::string {
    try {
      tsah::bench::resolveDataPath(f.data, f.cache, rel);
    } catch (const tsah::DataError& e) {
      return e.what();
    }
    return "resolved";
  };
  const std::string climbs = "must name a path inside the data folder (relative, without \"..\")";
  EXPECT_EQ(refusal("../../../etc/passwd"), "\"data:../../../etc/passwd\" " + climbs);
  EXPECT_EQ(refusal("/etc/passwd"), "\"data:/etc/passwd\" " + climbs);
  EXPECT_EQ(refusal("archives/packed.tar.xz/../../x"), "\"data:archives/packed.tar.xz/../../x\" " + climbs);
  // A symbolic link in the data folder, and one inside an archive, leading out of it.
  fs::create_symlink("/etc", f.data / "etc");
  EXPECT_EQ(refusal("etc/passwd"), "\"data:etc/passwd\" leads to /etc/passwd, outside the data folder (through a "
                                   "symbolic link)");
  fs::create_directories(f.root / "evil");
  fs::create_symlink("/etc/passwd", f.root / "evil" / "passwd.obj");
  ASSERT_TRUE(tsah::bench::runProcess({"tar", "-cJf", (f.data / "evil.tar.xz").string(), "-C",
                                       (f.root / "evil").string(), "passwd.obj"})
                  .ok());
  EXPECT_EQ(refusal("evil.tar.xz/passwd.obj"), "\"data:evil.tar.xz/passwd.obj\" leads to /etc/passwd, outside the "
                                               "data folder (through a symbolic link)");
  // What stays inside resolves, through an archive too.
  EXPECT_TRUE(fs::exists(tsah::bench::resolveDataPath(f.data, f.cache, "archives/packed.tar.xz/packed-wave/0001.obj")));
}

TEST(BenchData, BrokenArchivesAndMissingFoldersAreErrors) {
  const fs::path root = tsah::test::scratchDir();
  writeText(root / "data" / "bad.tar.xz", "this is not an xz stream");
  EXPECT_THROW(tsah::bench::unpackArchive(root / "data" / "bad.tar.xz", root / "cache"), tsah::Error);
  EXPECT_THROW(tsah::bench::scanDataFolder(root / "data", {root / "cache", {}}), tsah::Error);
  // Nothing half-unpacked is left in the cache.
  for (const auto& e : fs::directory_iterator(root / "cache")) ADD_FAILURE() << "left behind: " << e.path();
  EXPECT_THROW(tsah::bench::scanDataFolder(root / "no-such-folder", {root / "cache", {}}), tsah::Error);
  EXPECT_THROW(tsah::bench::explicitScene(root / "no-such-file.tanim"), tsah::Error);
}

TEST(BenchData, ExplicitScenesAndTheDefaultDataFolder) {
  DataFolder f;
  const SceneSource seq = tsah::bench::explicitScene(f.data / "sequences" / "wave" / "");
  EXPECT_EQ(seq.name, "wave");
  EXPECT_EQ(seq.kind, "sequence");
  const SceneSource model = tsah::bench::explicitScene(f.data / "models" / "Wave-Model.tanim");
  EXPECT_EQ(model.name, "wave-model");
  EXPECT_EQ(model.kind, "tanim");
  EXPECT_TRUE(tsah::bench::isFrameSequenceFolder(f.data / "sequences" / "wave"));
  EXPECT_FALSE(tsah::bench::isFrameSequenceFolder(f.data / "static"));
  EXPECT_FALSE(tsah::bench::isFrameSequenceFolder(f.data / "bart" / "stage"));

  EXPECT_EQ(tsah::bench::defaultDataFolder("given", "/nowhere"), fs::path("given"));
  const char* old = std::getenv("TSAH_DATA_DIR");
  const std::string saved = old ? old : "";
  ::setenv("TSAH_DATA_DIR", f.data.c_str(), 1);
  EXPECT_EQ(tsah::bench::defaultDataFolder("", "/nowhere"), f.data);
  ::unsetenv("TSAH_DATA_DIR");
  // ../shared/data next to the source folder.
  fs::create_directories(f.root / "shared" / "data");
  fs::create_directories(f.root / "checkout");
  EXPECT_EQ(tsah::bench::defaultDataFolder("", (f.root / "checkout").string()), fs::weakly_canonical(f.root / "shared" / "data"));
  EXPECT_EQ(tsah::bench::defaultDataFolder("", "/nowhere"), fs::path("..") / "shared" / "data");
  if (old) ::setenv("TSAH_DATA_DIR", saved.c_str(), 1);
}

TEST(BenchData, TheSharedDataFolderHoldsTheBenchmarkScenes) {
  const fs::path data = tsah::test::dataDir();
  if (!fs::exists(data / "bart" / "bart_aff_scenes.tar.xz") || !fs::exists(data / "sequences"))
    GTEST_SKIP() << "real data not present in " << data;
  const fs::path cache = fs::temp_directory_path() / ("tsah-bench-test-cache-" + std::to_string(::getuid()));
  const tsah::bench::DataScan scan = tsah::bench::scanDataFolder(data, {cache, {}});
  std::vector<std::string> names;
  for (const SceneSource& s : scan.scenes) names.push_back(s.name);
  EXPECT_EQ(names, (std::vector<std::string>{"faerie", "horse-collapse", "horse-gallop", "kitchen", "museum", "robot",
                                             "samba", "sydney"}));
  EXPECT_EQ(fs::path(byName(scan, "museum")->input).filename(), "museum5.aff");
  EXPECT_EQ(fs::path(byName(scan, "robot")->input).filename(), "Robot.aff");
  EXPECT_EQ(fs::path(byName(scan, "kitchen")->input).filename(), "kitchen.aff");
  bool museum7 = false;
  for (const auto& s : scan.skipped) museum7 = museum7 || s.path.find("museum7.aff") != std::string::npos;
  EXPECT_TRUE(museum7) << "museum7.aff needs animart7.aff, which the data does not have";
}

}  // namespace
