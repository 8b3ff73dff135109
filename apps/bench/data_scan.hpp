#pragma once
// Finding the benchmark's scenes: every real animation in a data folder, read as it is laid out
// (archives included), or inputs named on the command line.
//
// In a data folder:
//   *.tar.xz, *.txz, *.tar   unpacked into the cache folder (never into the data folder), then scanned
//   NAME.xz                  decompressed into the cache when NAME is an animation format; a
//                            compressed single static mesh (.obj/.off/.ply/.stl) is skipped
//   a folder of >= 2 meshes  an OBJ/PLY/OFF/STL sequence, named after the folder
//   a folder of *.aff        BART scenes: every .aff with an animation range (`a`) that no other .aff
//                            of the folder includes and whose includes all exist; named after the
//                            folder when it holds one such scene, else after the file
//   *.md2, *.tanim, *.gltf, *.glb, *.fbx, *.dae   one scene each, named after the file
//   single static meshes     skipped (not animations)
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace tsah::bench {

struct SceneSource {
  std::string name;    // short name used on the command line and in the report (horse-gallop, robot)
  std::string input;   // what anim::load reads (a folder, .aff, .md2, .tanim, ...)
  std::string kind;    // sequence, bart, md2, tanim, model
  std::string origin;  // where it came from in the data folder (an archive, a file), or the path given
};

struct SkippedEntry {
  std::string path;
  std::string reason;
};

struct DataScan {
  std::vector<SceneSource> scenes;  // sorted by name, names unique
  std::vector<SkippedEntry> skipped;
};

struct ScanOptions {
  std::filesystem::path cache;  // archives are unpacked below this folder (created when needed)
  std::function<void(const std::string&)> progress;  // "unpacking X" when an archive is unpacked; may be empty
};

// Scans a data folder as described above. Throws tsah::ConfigError when the folder does not exist,
// tsah::Failure when an archive cannot be unpacked.
DataScan scanDataFolder(const std::filesystem::path& folder, const ScanOptions& options);

// The BART scene files of a folder of .aff files (file names, sorted); files that look like scenes
// but include a missing file are added to `skipped` with the reason.
std::vector<std::string> bartSceneFiles(const std::filesystem::path& folder, std::vector<SkippedEntry>* skipped = nullptr);

// True when the folder holds at least two mesh files of one format (an animation as a frame sequence).
bool isFrameSequenceFolder(const std::filesystem::path& folder);

// Unpacks a .tar.xz/.txz/.tar archive (or decompresses a single .xz file) into a folder below
// `cache` named after the archive and its size and modification time, so a changed archive is
// unpacked again and an unchanged one only once. Unpacks into a staging folder first and renames
// it, so an interrupted run never leaves a half-unpacked cache behind. Returns the folder (for a
// single .xz file: the decompressed file). onUnpack is called just before real work starts (not
// when the cached copy is used). Throws tsah::Failure when tar/xz fail.
std::filesystem::path unpackArchive(const std::filesystem::path& archive, const std::filesystem::path& cache,
                                    const std::function<void()>& onUnpack = {});

// Resolves a scene file's "data:REL" object path (docs/scenes.md) against the data folder: REL
// may pass through an archive as if it were a folder (sequences/horse-gallop.tar.xz/horse-gallop)
// or end at a compressed file (static/bunny00.off.xz); those are unpacked into `cache` once
// (unpackArchive), never into the data folder.
std::string resolveDataPath(const std::filesystem::path& dataFolder, const std::filesystem::path& cache,
                            const std::string& rel);

// A scene for an input named on the command line (a file or folder anim::load reads).
SceneSource explicitScene(const std::filesystem::path& input);

// The data folder to use: `given` when not empty, else $TSAH_DATA_DIR, else ../shared/data next to
// the source checkout the program was built from, else ../shared/data relative to the working folder.
std::filesystem::path defaultDataFolder(const std::string& given, const std::string& sourceDir);

// Resolves scenes' "data:" paths (resolveDataPath) against defaultDataFolder(dataFolder, sourceDir),
// unpacking archives into `cache` (given, else $TSAH_CACHE_DIR, else $XDG_CACHE_HOME/tsah, else
// ~/.cache/tsah, else the temporary folder's tsah-cache): what `tsah` and the GPU two-level bench
// give anim::LoadOptions::resolveDataPath.
std::function<std::string(const std::string&)> dataPathResolver(const std::string& dataFolder, const std::string& cache,
                                                                const std::string& sourceDir);

}  // namespace tsah::bench
