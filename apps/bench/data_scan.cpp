#include "bench/data_scan.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <sys/statvfs.h>
#include <unistd.h>

#include "tsah/base/error.hpp"
#include "anim/scene.hpp"
#include "tsah/base/memory.hpp"
#include "bench/process.hpp"

namespace tsah::bench {

namespace fs = std::filesystem;

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Extensions anim::load reads as one mesh per file (a single file is a static scene).
bool isMeshExtension(const std::string& ext) {
  return ext == ".obj" || ext == ".off" || ext == ".ply" || ext == ".stl" || ext == ".om";
}
// Single files that hold a whole animation.
std::string animationKind(const std::string& ext) {
  if (ext == ".md2") return "md2";
  if (ext == ".tanim") return "tanim";
  if (ext == ".gltf" || ext == ".glb" || ext == ".fbx" || ext == ".dae") return "model";
  if (ext == ".aff") return "bart";
  return {};
}

bool isTarArchive(const std::string& lowerName) {
  return endsWith(lowerName, ".tar.xz") || endsWith(lowerName, ".txz") || endsWith(lowerName, ".tar");
}

std::vector<fs::directory_entry> sortedEntries(const fs::path& dir) {
  std::vector<fs::directory_entry> entries;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) entries.push_back(e);
  if (ec) throw tsah::FileError(dir.string(), "cannot list the folder (" + ec.message() + ")");
  std::sort(entries.begin(), entries.end(),
            [](const fs::directory_entry& a, const fs::directory_entry& b) { return a.path() < b.path(); });
  return entries;
}

// The include targets and whether an animation range (`a t0 t1 frames`) appears in one .aff file.
struct AffSummary {
  std::vector<std::string> includes;
  bool hasAnimationRange = false;
};

bool isNumber(const std::string& s) {
  if (s.empty()) return false;
  char* end = nullptr;
  std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size();
}

AffSummary summarizeAff(const fs::path& file) {
  AffSummary summary;
  std::ifstream in(file);
  if (!in) throw tsah::FileError(file.string(), "cannot be read");
  std::vector<std::string> tokens;
  std::string line;
  while (std::getline(in, line)) {
    // Comments run from '#' or '%' to the end of the line; braces are tokens even when glued.
    const std::size_t comment = line.find_first_of("#%");
    if (comment != std::string::npos) line.resize(comment);
    for (char& c : line)
      if (c == '{' || c == '}') c = ' ';
    std::stringstream words(line);
    std::string w;
    while (words >> w) tokens.push_back(w);
  }
  for (std::size_t i = 0; i < tokens.size(); ++i) {
    if (tokens[i] == "i" && i + 2 < tokens.size() && isNumber(tokens[i + 1])) summary.includes.push_back(tokens[i + 2]);
    if (tokens[i] == "a" && i + 3 < tokens.size() && isNumber(tokens[i + 1]) && isNumber(tokens[i + 2]) &&
        isNumber(tokens[i + 3]))
      summary.hasAnimationRange = true;
  }
  return summary;
}

// The first include (depth first) of `file` that does not exist in `folder`, or empty.
std::string missingInclude(const std::string& file, const fs::path& folder, const std::map<std::string, AffSummary>& affs,
                           std::set<std::string>& visited) {
  if (!visited.insert(file).second) return {};
  const auto it = affs.find(file);
  if (it == affs.end()) return file;
  for (const std::string& inc : it->second.includes) {
    if (affs.count(inc) == 0) {
      std::error_code ec;
      if (!fs::is_regular_file(folder / inc, ec)) return inc;
      continue;  // an included file of another type (a texture list, ...): present is enough
    }
    const std::string missing = missingInclude(inc, folder, affs, visited);
    if (!missing.empty()) return missing;
  }
  return {};
}

std::string hex32(uint64_t v) {
  char text[17];
  std::snprintf(text, sizeof text, "%08x", static_cast<unsigned>((v ^ (v >> 32)) & 0xffffffffu));
  return text;
}

struct Scanner {
  const ScanOptions& options;
  const fs::path root;
  DataScan out;

  std::string shown(const fs::path& p) const {
    std::error_code ec;
    const fs::path rel = fs::relative(p, root, ec);
    return !ec && !rel.empty() && rel.native()[0] != '.' ? rel.string() : p.string();
  }

  void add(std::string name, const fs::path& input, const std::string& kind, const std::string& origin) {
    out.scenes.push_back({lower(std::move(name)), input.string(), kind, origin});
  }

  void skip(const fs::path& p, const std::string& reason) { out.skipped.push_back({shown(p), reason}); }

  void scanFolder(const fs::path& dir, const std::string& origin, int depth) {
    if (depth > 8) return;
    if (isFrameSequenceFolder(dir)) {
      add(dir.filename().string(), dir, "sequence", origin.empty() ? shown(dir) : origin);
      return;
    }
    const std::vector<fs::directory_entry> entries = sortedEntries(dir);
    bool hasAff = false;
    for (const auto& e : entries)
      if (e.is_regular_file() && lower(e.path().extension().string()) == ".aff") hasAff = true;
    if (hasAff) {
      std::vector<SkippedEntry> skipped;
      const std::vector<std::string> scenes = bartSceneFiles(dir, &skipped);
      for (const std::string& file : scenes) {
        const std::string name = scenes.size() == 1 ? dir.filename().string() : fs::path(file).stem().string();
        add(name, dir / file, "bart", origin.empty() ? shown(dir / file) : origin + ": " + dir.filename().string() + "/" + file);
      }
      for (const SkippedEntry& s : skipped) skip(dir / s.path, s.reason);
    }
    for (const auto& e : entries) {
      const fs::path& p = e.path();
      const std::string name = lower(p.filename().string());
      if (e.is_directory()) {
        scanFolder(p, origin, depth + 1);
        continue;
      }
      if (!e.is_regular_file()) continue;
      const std::string ext = lower(p.extension().string());
      if (isTarArchive(name)) {
        const fs::path unpacked = unpackArchive(p, options.cache, [&] {
          if (options.progress) options.progress("unpacking " + shown(p));
        });
        scanFolder(unpacked, shown(p), depth + 1);
      } else if (ext == ".xz") {
        const fs::path inner = p.stem();
        const std::string innerExt = lower(inner.extension().string());
        if (isMeshExtension(innerExt)) {
          skip(p, "a single static mesh, not an animation");
        } else if (const std::string kind = animationKind(innerExt); !kind.empty() && kind != "bart") {
          const fs::path file = unpackArchive(p, options.cache, [&] {
            if (options.progress) options.progress("decompressing " + shown(p));
          });
          add(inner.stem().string(), file, kind, shown(p));
        } else {
          skip(p, "compressed file of an unknown kind");
        }
      } else if (const std::string kind = animationKind(ext); !kind.empty() && kind != "bart") {
        add(p.stem().string(), p, kind, origin.empty() ? shown(p) : origin);
      } else if (isMeshExtension(ext)) {
        skip(p, "a single static mesh, not an animation");
      }
    }
  }
};

// What unpacking `archive` will write: for xz, the uncompressed size its index declares (for a
// .tar.xz the tar stream, which bounds the files in it); a plain .tar is its own size.
uint64_t expandedSize(const fs::path& archive, bool xz, uint64_t size) {
  if (!xz) return size;
  const ProcessResult r = runProcess({"xz", "--robot", "--list", "--", fs::absolute(archive).string()});
  std::istringstream lines(r.output);
  std::string line;
  while (r.ok() && std::getline(lines, line)) {
    // totals <streams> <blocks> <compressed> <uncompressed> ...
    std::istringstream fields(line);
    std::string kind;
    uint64_t streams = 0, blocks = 0, compressed = 0, uncompressed = 0;
    if (fields >> kind >> streams >> blocks >> compressed >> uncompressed && kind == "totals") return uncompressed;
  }
  throw tsah::FileError(archive.string(), "cannot read the size it expands to (xz --list" +
                                              (r.output.empty() ? std::string(")") : ": " + r.output.substr(0, r.output.find('\n')) + ")"));
}

// Refuses an archive whose expanded size does not fit, before any of it is written: the disk of
// the cache (the same headroom as memory: at most kMemoryBudgetFraction of the free space) and the
// memory budget (the scenes it holds are read into memory).
void checkUnpackFits(const fs::path& archive, uint64_t expanded, const fs::path& cache) {
  struct statvfs disk {};
  if (::statvfs(cache.c_str(), &disk) == 0) {
    const uint64_t free = uint64_t(disk.f_bavail) * disk.f_frsize;
    if (double(expanded) > double(free) * kMemoryBudgetFraction)
      throw tsah::Failure(archive.string() + ": expands to " + std::to_string(expanded >> 20) + " MiB, more than " +
                          std::to_string(int(kMemoryBudgetFraction * 100)) + "% of the " + std::to_string(free >> 20) +
                          " MiB free in " + cache.string());
  }
  tsah::checkFitsInMemory(std::size_t(expanded), archive.string(), "unpacking");
}

}  // namespace

bool isFrameSequenceFolder(const fs::path& folder) {
  std::map<std::string, int> counts;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec)) {
    if (!e.is_regular_file()) continue;
    const std::string ext = lower(e.path().extension().string());
    if (isMeshExtension(ext) && ++counts[ext] >= 2) return true;
  }
  return false;
}

std::vector<std::string> bartSceneFiles(const fs::path& folder, std::vector<SkippedEntry>* skipped) {
  std::map<std::string, AffSummary> affs;
  for (const auto& e : sortedEntries(folder))
    if (e.is_regular_file() && lower(e.path().extension().string()) == ".aff")
      affs[e.path().filename().string()] = summarizeAff(e.path());
  std::set<std::string> included;
  for (const auto& [file, summary] : affs) included.insert(summary.includes.begin(), summary.includes.end());
  std::vector<std::string> scenes;
  for (const auto& [file, summary] : affs) {
    if (!summary.hasAnimationRange || included.count(file)) continue;
    std::set<std::string> visited;
    const std::string missing = missingInclude(file, folder, affs, visited);
    if (!missing.empty()) {
      if (skipped) skipped->push_back({file, "includes " + missing + ", which is not in the folder"});
      continue;
    }
    scenes.push_back(file);
  }
  return scenes;
}

fs::path unpackArchive(const fs::path& archive, const fs::path& cache, const std::function<void()>& onUnpack) {
  std::error_code ec;
  const auto size = fs::file_size(archive, ec);
  if (ec) throw tsah::FileError(archive.string(), "cannot be read (" + ec.message() + ")");
  const auto mtime = fs::last_write_time(archive, ec).time_since_epoch().count();
  std::string base = archive.filename().string();
  const std::string name = lower(base);
  const bool tar = isTarArchive(name);
  for (const char* suffix : {".tar.xz", ".txz", ".tar", ".xz"})
    if (endsWith(name, suffix)) {
      base.resize(base.size() - std::string(suffix).size());
      break;
    }
  const fs::path target = cache / (base + "-" + hex32(uint64_t(size) * 0x9e3779b97f4a7c15ull ^ uint64_t(mtime)));
  const fs::path result = tar ? target : target / base;
  if (fs::exists(target / ".complete", ec)) return result;

  fs::create_directories(cache, ec);
  if (ec) throw tsah::Failure(cache.string() + ": cannot create the cache folder (" + ec.message() + ")");
  checkUnpackFits(archive, expandedSize(archive, !endsWith(name, ".tar"), uint64_t(size)), cache);
  if (onUnpack) onUnpack();
  const fs::path staging = cache / (".staging-" + base + "-" + std::to_string(::getpid()));
  fs::remove_all(staging, ec);
  fs::create_directories(staging, ec);
  if (ec) throw tsah::Failure(staging.string() + ": cannot be created (" + ec.message() + ")");
  ProcessResult r;
  if (tar) {
    r = runProcess({"tar", endsWith(name, ".tar") ? "-xf" : "-xJf", fs::absolute(archive).string(), "-C", staging.string()});
  } else {
    r = runProcess({"xz", "-dc", fs::absolute(archive).string()}, (staging / base).string());
  }
  if (!r.ok()) {
    fs::remove_all(staging, ec);
    std::string why = r.started ? "exit status " + std::to_string(r.status) : "the program is not installed";
    if (!r.output.empty()) why += ": " + r.output.substr(0, r.output.find('\n'));
    throw tsah::Failure(archive.string() + ": cannot unpack (" + std::string(tar ? "tar" : "xz") + ", " + why + ")");
  }
  if (std::FILE* marker = std::fopen((staging / ".complete").c_str(), "w")) std::fclose(marker);
  fs::rename(staging, target, ec);  // another run that won the race leaves its own complete copy
  if (ec) fs::remove_all(staging, ec);
  if (!fs::exists(target / ".complete", ec)) throw tsah::Failure(target.string() + ": unpacking did not complete");
  return result;
}

DataScan scanDataFolder(const fs::path& folder, const ScanOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw tsah::ConfigError(folder.string() + ": the data folder does not exist");
  Scanner scanner{options, fs::weakly_canonical(folder), {}};
  scanner.scanFolder(folder, {}, 0);
  DataScan out = std::move(scanner.out);
  std::stable_sort(out.scenes.begin(), out.scenes.end(),
                   [](const SceneSource& a, const SceneSource& b) { return a.name < b.name; });
  // Names must be unique: a second scene of the same name gets a numbered suffix.
  std::map<std::string, int> seen;
  for (SceneSource& s : out.scenes)
    if (int n = ++seen[s.name]; n > 1) s.name += "-" + std::to_string(n);
  return out;
}

SceneSource explicitScene(const fs::path& input) {
  std::error_code ec;
  if (!fs::exists(input, ec)) throw tsah::FileError(input.string(), "no such file or folder");
  SceneSource s;
  s.input = input.string();
  s.origin = input.string();
  const fs::path clean = input.has_filename() ? input : input.parent_path();
  if (fs::is_directory(input, ec)) {
    s.name = clean.filename().string();
    s.kind = "sequence";
  } else {
    s.name = clean.stem().string();
    const std::string kind = animationKind(lower(clean.extension().string()));
    s.kind = kind.empty() ? "file" : kind;
  }
  s.name = lower(s.name);
  return s;
}

std::string resolveDataPath(const fs::path& dataFolder, const fs::path& cache, const std::string& rel) {
  anim::checkDataPath(rel);
  fs::path at = dataFolder;
  fs::path root = dataFolder;  // what `at` must stay inside: the data folder, or the archive unpacked last
  const fs::path relative(rel);
  for (auto part = relative.begin(); part != relative.end(); ++part) {
    at /= *part;
    std::error_code ec;
    if (!fs::is_regular_file(at, ec)) continue;
    std::string name = at.filename().string();
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    const bool last = std::next(part) == relative.end();
    if ((!last && isTarArchive(name)) || (last && endsWith(name, ".xz") && !isTarArchive(name))) {
      anim::requireInsideDataFolder(root, at, rel);
      at = unpackArchive(at, cache);
      root = at;
    }
  }
  anim::requireInsideDataFolder(root, at, rel);
  return at.string();
}

fs::path defaultDataFolder(const std::string& given, const std::string& sourceDir) {
  if (!given.empty()) return given;
  if (const char* env = std::getenv("TSAH_DATA_DIR"); env && *env) return env;
  std::error_code ec;
  if (!sourceDir.empty()) {
    const fs::path candidate = fs::path(sourceDir) / ".." / "shared" / "data";
    if (fs::is_directory(candidate, ec)) return fs::weakly_canonical(candidate, ec);
  }
  return fs::path("..") / "shared" / "data";
}

std::function<std::string(const std::string&)> dataPathResolver(const std::string& dataFolder, const std::string& cache,
                                                                const std::string& sourceDir) {
  const fs::path data = defaultDataFolder(dataFolder, sourceDir);
  fs::path unpacked = cache;
  if (unpacked.empty()) {
    if (const char* c = std::getenv("TSAH_CACHE_DIR"); c && *c) unpacked = c;
    else if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) unpacked = fs::path(x) / "tsah";
    else if (const char* h = std::getenv("HOME"); h && *h) unpacked = fs::path(h) / ".cache" / "tsah";
    else unpacked = fs::temp_directory_path() / "tsah-cache";
  }
  return [data, unpacked](const std::string& rel) { return resolveDataPath(data, unpacked, rel); };
}

}  // namespace tsah::bench
