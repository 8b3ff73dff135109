#include "anim/mesh_sequence.hpp"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <glob.h>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "frame_pattern.hpp"
#include "mesh_check.hpp"

namespace anim {

namespace fs = std::filesystem;

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

// Fans a polygon (n >= 3 vertex indices) into triangles.
void fanTriangulate(std::span<const uint32_t> polygon, std::vector<uint32_t>& out) {
  for (std::size_t i = 1; i + 1 < polygon.size(); ++i) {
    out.push_back(polygon[0]);
    out.push_back(polygon[i]);
    out.push_back(polygon[i + 1]);
  }
}

// OBJ is the format of every real sequence, so it gets a dedicated reader: exact vertex and face
// order (no merging or dropping of non-manifold faces as a half-edge mesh would do), and fast.
}  // namespace

MeshFrame decodeObj(std::span<const uint8_t> bytes, const std::string& path) {
  const char* p = reinterpret_cast<const char*>(bytes.data());
  const char* end = p + bytes.size();
  MeshFrame mesh;
  std::vector<uint32_t> polygon;
  std::size_t line = 1;
  auto fail = [&](const std::string& what) -> void {
    throw tsah::FileError(path, "line " + std::to_string(line) + ": " + what);
  };
  auto skipSpaces = [&] {
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\r')) ++p;
  };
  auto skipLine = [&] {
    while (p < end && *p != '\n') ++p;
  };
  while (p < end) {
    skipSpaces();
    if (p < end && *p == 'v' && p + 1 < end && (p[1] == ' ' || p[1] == '\t')) {
      p += 2;
      for (int a = 0; a < 3; ++a) {
        skipSpaces();
        float value = 0.0f;
        auto [next, ec] = std::from_chars(p, end, value);
        if (ec != std::errc()) fail("vertex needs three numeric coordinates");
        mesh.positions.push_back(value);
        p = next;
      }
    } else if (p < end && *p == 'f' && p + 1 < end && (p[1] == ' ' || p[1] == '\t')) {
      p += 2;
      polygon.clear();
      const long vertexCount = long(mesh.positions.size() / 3);
      for (;;) {
        skipSpaces();
        if (p >= end || *p == '\n' || *p == '#') break;
        long index = 0;
        auto [next, ec] = std::from_chars(p, end, index);
        if (ec != std::errc()) fail("face entry is not a vertex index");
        p = next;
        while (p < end && *p == '/') {  // skip /vt/vn
          ++p;
          long ignored;
          auto [n2, ec2] = std::from_chars(p, end, ignored);
          if (ec2 == std::errc()) p = n2;
        }
        if (index < 0) index = vertexCount + index + 1;  // relative index
        if (index < 1 || index > vertexCount)
          fail("face references vertex " + std::to_string(index) + " but " +
               std::to_string(vertexCount) + " are defined");
        polygon.push_back(uint32_t(index - 1));
      }
      if (polygon.size() < 3) fail("face with fewer than 3 vertices");
      ++mesh.faceCount;
      if (polygon.size() > 3) ++mesh.polygonsTriangulated;
      fanTriangulate(polygon, mesh.indices);
    }
    skipLine();
    if (p < end) ++p;
    ++line;
  }
  if (mesh.positions.empty()) throw tsah::FileError(path, "no vertices");
  return mesh;
}

namespace {

// Everything else through OpenMesh. Its messages (e.g. dropped non-manifold faces) are captured:
// a face OpenMesh could not add would silently change the topology, so that is an error.
// Our own pass over the file first (mesh_check.hpp): OpenMesh drops faces that reference missing
// vertices and allocates whatever a header claims; afterwards its counts must match the header's.
MeshFrame readWithOpenMesh(const std::string& path) {
  const DeclaredMesh declared = checkMeshFile(path, tsah::readFile(path));
  using Mesh = OpenMesh::PolyMesh_ArrayKernelT<>;
  Mesh mesh;
  // omerr/omlog are process-wide: connect them once to one captured stream (OpenMesh never frees a
  // connection, so connecting per call would leak) and serialize reads through OpenMesh.
  static std::mutex openMeshStreams;
  static std::ostringstream messages;
  bool ok;
  std::string complaints;
  {
    std::lock_guard lock(openMeshStreams);
    static const bool connected = [] {
      omerr().connect(messages);
      omerr().disconnect(std::cerr);  // libraries never print (OpenMesh drops this target unfreed)
      omlog().disable();
      omout().disable();
      return true;
    }();
    (void)connected;
    messages.str("");
    OpenMesh::IO::Options options;
    ok = OpenMesh::IO::read_mesh(mesh, path, options);
    complaints = messages.str();
  }
  if (!ok) throw tsah::FileError(path, "OpenMesh cannot read this file");
  if (complaints.find("complex") != std::string::npos)
    throw tsah::FileError(path, "has non-manifold faces that the mesh reader drops; convert it to OBJ");
  if (declared.known && (mesh.n_vertices() != declared.vertices || mesh.n_faces() != declared.faces))
    throw tsah::FileError(path, "the mesh reader kept " + std::to_string(mesh.n_vertices()) + " of " +
                                std::to_string(declared.vertices) + " vertices and " + std::to_string(mesh.n_faces()) +
                                " of " + std::to_string(declared.faces) +
                                " faces (it drops degenerate and non-manifold faces); convert it to OBJ");
  MeshFrame out;
  out.positions.reserve(mesh.n_vertices() * 3);
  for (auto v : mesh.vertices()) {
    const auto& q = mesh.point(v);
    out.positions.insert(out.positions.end(), {q[0], q[1], q[2]});
  }
  std::vector<uint32_t> polygon;
  for (auto f : mesh.faces()) {
    polygon.clear();
    for (auto v : mesh.fv_range(f)) polygon.push_back(uint32_t(v.idx()));
    ++out.faceCount;
    if (polygon.size() > 3) ++out.polygonsTriangulated;
    fanTriangulate(polygon, out.indices);
  }
  if (out.positions.empty()) throw tsah::FileError(path, "no vertices");
  return out;
}

bool isHiddenOrBackup(const fs::path& p) {
  const std::string name = p.filename().string();
  return name.empty() || name[0] == '.' || name.back() == '~';
}

}  // namespace

bool isMeshFile(const std::string& path) {
  const std::string ext = lower(fs::path(path).extension().string());
  return ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".stl" || ext == ".om";
}

MeshFrame readMesh(const std::string& path) {
  if (lower(fs::path(path).extension().string()) == ".obj") return decodeObj(tsah::readFile(path), path);
  return readWithOpenMesh(path);
}

bool naturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i]));
    const bool db = std::isdigit(static_cast<unsigned char>(b[j]));
    if (da && db) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      // Compare by value: strip leading zeros, then longer means larger.
      std::size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

FrameList listFrames(const std::string& spec) {
  FrameList list;
  std::error_code ec;
  if (spec.find('%') != std::string::npos) {
    const fs::path p(spec);
    const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
    if (!fs::is_directory(dir, ec)) throw tsah::FileError(spec, "folder " + dir.string() + " does not exist");
    const detail::FramePatternParse parsed = detail::parseFramePattern(p.filename().string());
    if (!parsed.pattern) throw tsah::FileError(spec, parsed.error);
    std::vector<std::pair<uint64_t, std::string>> numbered;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      if (!entry.is_regular_file()) continue;
      if (const auto number = parsed.pattern->match(entry.path().filename().string()))
        numbered.emplace_back(*number, entry.path().string());
    }
    std::sort(numbered.begin(), numbered.end());
    for (auto& [n, file] : numbered) list.files.push_back(std::move(file));
  } else if (spec.find_first_of("*?[") != std::string::npos) {
    glob_t g{};
    const int rc = ::glob(spec.c_str(), 0, nullptr, &g);
    if (rc == 0)
      for (std::size_t i = 0; i < g.gl_pathc; ++i)
        if (fs::is_regular_file(g.gl_pathv[i], ec) && !isHiddenOrBackup(g.gl_pathv[i]))
          list.files.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    std::sort(list.files.begin(), list.files.end(), naturalLess);
  } else if (fs::is_directory(spec, ec)) {
    for (const auto& entry : fs::directory_iterator(spec, ec))
      if (entry.is_regular_file() && isMeshFile(entry.path().string()) && !isHiddenOrBackup(entry.path()))
        list.files.push_back(entry.path().string());
    std::sort(list.files.begin(), list.files.end(), naturalLess);
  } else {
    throw tsah::FileError(spec, "not a frame pattern, glob or directory");
  }
  if (list.files.empty()) throw tsah::FileError(spec, "matches no mesh files");
  return list;
}

FrameList readManifest(const std::string& path) { return decodeManifest(tsah::readFile(path, std::size_t(1) << 28), path); }

FrameList decodeManifest(std::span<const uint8_t> bytes, const std::string& path) {
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(bytes.begin(), bytes.end());
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for 1e999
    std::string what = e.what();
    if (const auto end = what.find("] "); what.rfind("[json.exception", 0) == 0 && end != std::string::npos)
      what.erase(0, end + 2);  // the library's "[json.exception.parse_error.101] " tag
    throw tsah::FileError(path, "invalid JSON: " + what);
  }
  const nlohmann::json* frames = &doc;
  if (doc.is_object()) {
    if (!doc.contains("frames")) throw tsah::FileError(path, "manifest object has no \"frames\" array");
    frames = &doc["frames"];
  }
  if (!frames->is_array() || frames->empty())
    throw tsah::FileError(path, "manifest \"frames\" must be a non-empty array");
  const fs::path base = fs::path(path).parent_path();
  FrameList list;
  std::size_t withTime = 0;
  for (std::size_t i = 0; i < frames->size(); ++i) {
    const auto& f = (*frames)[i];
    std::string file;
    if (f.is_string()) {
      file = f.get<std::string>();
    } else if (f.is_object() && f.contains("file") && f["file"].is_string()) {
      file = f["file"].get<std::string>();
      if (f.contains("time")) {
        if (!f["time"].is_number()) throw tsah::FileError(path, "frame " + std::to_string(i) + ": \"time\" is not a number");
        list.times.push_back(f["time"].get<double>());
        ++withTime;
      }
    } else {
      throw tsah::FileError(path, "frame " + std::to_string(i) + " is neither a file name nor {\"file\": ...}");
    }
    const fs::path fp(file);
    list.files.push_back(fp.is_absolute() ? fp.string() : (base / fp).string());
  }
  if (withTime != 0 && withTime != list.files.size())
    throw tsah::FileError(path, "times given for " + std::to_string(withTime) + " of " +
                                std::to_string(list.files.size()) + " frames: give all or none");
  return list;
}

Animation importSequence(const FrameList& frames, const LoadOptions& options, std::string name) {
  const std::size_t n = frames.files.size();
  if (n == 0) throw tsah::DataError(name + ": no frames");
  if (!frames.times.empty() && frames.times.size() != n) throw tsah::DataError(name + ": times do not match frames");

  const MeshFrame first = readMesh(frames.files[0]);
  const std::size_t perFrame = first.positions.size();
  tsah::requireMemory(uint64_t(perFrame) * n * sizeof(float), name,
                std::to_string(n) + " frames of " + std::to_string(perFrame / 3) + " vertices");
  std::vector<float> positions(perFrame * n);
  std::copy(first.positions.begin(), first.positions.end(), positions.begin());

  // Read the other frames in parallel; each checks its topology against the first frame.
  std::atomic<std::size_t> next{1}, done{1};
  std::mutex errorMutex;
  std::exception_ptr firstError;
  std::size_t firstErrorFrame = n;
  auto worker = [&] {
    for (std::size_t i = next++; i < n; i = next++) {
      try {
        MeshFrame m = readMesh(frames.files[i]);
        if (m.positions.size() != perFrame)
          throw tsah::FileError(frames.files[i], "has " + std::to_string(m.positions.size() / 3) +
                                                 " vertices but the first frame (" + frames.files[0] +
                                                 ") has " + std::to_string(perFrame / 3));
        if (m.indices != first.indices) {
          if (m.indices.size() != first.indices.size())
            throw tsah::FileError(frames.files[i], "has " + std::to_string(m.indices.size() / 3) +
                                                   " triangles but the first frame (" + frames.files[0] +
                                                   ") has " + std::to_string(first.indices.size() / 3));
          const auto mismatch = std::mismatch(m.indices.begin(), m.indices.end(), first.indices.begin());
          throw tsah::FileError(frames.files[i],
                            "triangle " + std::to_string((mismatch.first - m.indices.begin()) / 3) +
                                " differs from the first frame (" + frames.files[0] + ")");
        }
        std::copy(m.positions.begin(), m.positions.end(), positions.begin() + std::ptrdiff_t(i * perFrame));
      } catch (...) {
        std::lock_guard lock(errorMutex);
        if (i < firstErrorFrame) {  // report the first differing file, whatever the thread timing
          firstErrorFrame = i;
          firstError = std::current_exception();
        }
      }
      const std::size_t d = ++done;
      if (options.progress) {
        std::lock_guard lock(errorMutex);
        options.progress(d, n);
      }
    }
  };
  const unsigned threads = std::max(1u, std::min<unsigned>(std::thread::hardware_concurrency(), unsigned(n - 1)));
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (firstError) std::rethrow_exception(firstError);

  std::vector<double> times = frames.times;
  if (times.empty())
    for (std::size_t i = 0; i < n; ++i) times.push_back(double(i));
  for (std::size_t i = 1; i < times.size(); ++i)
    if (!(times[i] > times[i - 1]))
      throw tsah::FileError(frames.files[i], "frame time " + std::to_string(times[i]) +
                                             " is not after the previous frame's");
  // The Animation constructor checks the coordinates too; name the frame file in that message.
  if (const std::size_t bad = firstBadCoordinate(positions); bad < positions.size())
    throw tsah::FileError(frames.files[bad / perFrame],
                      "vertex " + std::to_string((bad % perFrame) / 3) + " " + describeBadCoordinate(positions[bad]));
  if (first.indices.empty()) throw tsah::FileError(frames.files[0], "has no faces");
  // The constructor's whole-model checks (a model too small for float32 areas) name the file when
  // there is one; the animation keeps its name.
  Animation a(first.indices, uint32_t(perFrame / 3), std::move(positions), std::move(times),
              n == 1 ? frames.files[0] : name);
  a.setName(std::move(name));
  return a;
}

}  // namespace anim
