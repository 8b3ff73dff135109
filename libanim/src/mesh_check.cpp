#include "mesh_check.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <vector>

#include "anim/animation.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"

namespace anim {

namespace {

// Whitespace-separated tokens of a text section; `line` follows the newlines for messages.
class Tokens {
 public:
  Tokens(std::span<const uint8_t> bytes, std::size_t offset)
      : p_(reinterpret_cast<const char*>(bytes.data()) + offset),
        end_(reinterpret_cast<const char*>(bytes.data()) + bytes.size()) {}
  // Next token, or an empty view at the end. With `stopAtLine`, a newline ends the token list of a
  // line (returns empty once; the next call continues on the next line).
  std::string_view next(bool skipComments = false) {
    for (;;) {
      while (p_ < end_ && std::isspace(static_cast<unsigned char>(*p_))) ++p_;
      if (skipComments && p_ < end_ && *p_ == '#') {
        while (p_ < end_ && *p_ != '\n') ++p_;
        continue;
      }
      break;
    }
    const char* start = p_;
    while (p_ < end_ && !std::isspace(static_cast<unsigned char>(*p_))) ++p_;
    return {start, std::size_t(p_ - start)};
  }
  // Rest of the current line (OFF vertex and face lines carry optional colours/normals after the
  // values we check).
  void skipLine() {
    while (p_ < end_ && *p_ != '\n') ++p_;
  }
  // Next token of the current line, or empty when the line ends first.
  std::string_view nextOnLine() {
    while (p_ < end_ && *p_ != '\n' && std::isspace(static_cast<unsigned char>(*p_))) ++p_;
    if (p_ >= end_ || *p_ == '\n') return {};
    return next();
  }
  bool atEnd() const { return p_ >= end_; }

 private:
  const char* p_;
  const char* end_;
};

bool parseNumber(std::string_view token, double& value) {
  auto [next, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  return !token.empty() && ec == std::errc() && next == token.data() + token.size();
}

bool parseCount(std::string_view token, uint64_t& value) {
  auto [next, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  return !token.empty() && ec == std::errc() && next == token.data() + token.size();
}

// Checks that vertices * vertexBytes + faces * faceBytes fits in `available` (overflow-safe), then
// that the reader's structures fit in memory.
void checkCounts(const std::string& path, uint64_t vertices, uint64_t faces, uint64_t vertexBytes, uint64_t faceBytes,
                 uint64_t available) {
  uint64_t a = 0, b = 0, need = 0;
  const bool overflow = __builtin_mul_overflow(vertices, vertexBytes, &a) ||
                        __builtin_mul_overflow(faces, faceBytes, &b) || __builtin_add_overflow(a, b, &need);
  if (overflow || need > available)
    throw tsah::FileError(path, "header declares " + std::to_string(vertices) + " vertices and " +
                                std::to_string(faces) + " faces (at least " +
                                (overflow ? std::string("2^64") : std::to_string(need)) +
                                " bytes), but only " + std::to_string(available) + " bytes follow it");
  // OpenMesh's half-edge mesh: about 48 bytes per vertex and 80 per face (with their half-edges).
  tsah::requireMemory(vertices * 48 + faces * 80, path,
                "reading " + std::to_string(vertices) + " vertices and " + std::to_string(faces) + " faces");
}

void checkCoordinate(const std::string& path, uint64_t vertex, double value) {
  if (!(std::fabs(value) <= double(kMaxCoordinate)))
    throw tsah::FileError(path, "vertex " + std::to_string(vertex) + " " + describeBadCoordinate(float(value)));
}

void checkFaceIndex(const std::string& path, uint64_t face, int64_t index, uint64_t vertices) {
  if (index < 0 || uint64_t(index) >= vertices)
    throw tsah::FileError(path, "face " + std::to_string(face) + " references vertex " + std::to_string(index) +
                                " but the file has " + std::to_string(vertices) + " vertices (0.." +
                                std::to_string(vertices == 0 ? 0 : vertices - 1) + ")");
}

void checkFaceSize(const std::string& path, uint64_t face, uint64_t size) {
  if (size < 3) throw tsah::FileError(path, "face " + std::to_string(face) + " has " + std::to_string(size) +
                                            " vertices (at least 3 needed)");
}

// ---- OFF -----------------------------------------------------------------------------------------

DeclaredMesh checkOff(const std::string& path, std::span<const uint8_t> bytes) {
  Tokens in(bytes, 0);
  const std::string_view magic = in.next(true);
  if (magic.size() < 3 || magic.substr(magic.size() - 3) != "OFF")
    throw tsah::FileError(path, "not an OFF file (the first word is not OFF)");
  if (magic.find('4') != std::string_view::npos || magic.find('n') != std::string_view::npos)
    throw tsah::FileError(path, "4D and n-dimensional OFF files are not supported");
  // OpenMesh reads the keyword line whole and the counts from the lines after it: anything else on
  // the keyword line would make the two readers disagree about the counts.
  std::string_view word = in.nextOnLine();
  const bool binary = word == "BINARY";
  if (binary) word = in.nextOnLine();
  if (!word.empty())
    throw tsah::FileError(path, "the " + std::string(magic) + " line holds '" + std::string(word) +
                                "' after the keyword (the counts go on the next line)");
  uint64_t counts[3] = {};
  for (int i = 0; i < 3; ++i) {
    word = in.next(true);
    if (!parseCount(word, counts[i]))
      throw tsah::FileError(path, "header needs the vertex, face and edge counts, got '" + std::string(word) + "'");
  }
  if (counts[2] > 0xffffffffu) throw tsah::FileError(path, "edge count " + std::to_string(counts[2]) + " is absurd");
  const DeclaredMesh declared{true, counts[0], counts[1]};
  if (binary) {  // binary OFF: 3 floats per vertex, at least 4 ints per face
    checkCounts(path, declared.vertices, declared.faces, 12, 16, bytes.size());
    return declared;
  }
  checkCounts(path, declared.vertices, declared.faces, 6, 8, bytes.size());
  for (uint64_t v = 0; v < declared.vertices; ++v) {
    for (int a = 0; a < 3; ++a) {
      const std::string_view token = in.next(true);
      double value = 0;
      if (!parseNumber(token, value))
        throw tsah::FileError(path, "vertex " + std::to_string(v) + ": coordinate " + std::string(1, char('x' + a)) +
                                    (token.empty() ? " is missing (the file ends early)"
                                                   : " is not a number: '" + std::string(token) + "'"));
      checkCoordinate(path, v, value);
    }
    in.skipLine();  // colours, normals, texture coordinates
  }
  for (uint64_t f = 0; f < declared.faces; ++f) {
    const std::string_view token = in.next(true);
    uint64_t n = 0;
    if (!parseCount(token, n))
      throw tsah::FileError(path, "face " + std::to_string(f) + (token.empty() ? " is missing (the file ends early)"
                                                                        : ": bad vertex count '" + std::string(token) + "'"));
    checkFaceSize(path, f, n);
    for (uint64_t k = 0; k < n; ++k) {
      const std::string_view t = in.next(true);
      int64_t index = -1;
      auto [next, ec] = std::from_chars(t.data(), t.data() + t.size(), index);
      if (t.empty() || ec != std::errc() || next != t.data() + t.size())
        throw tsah::FileError(path, "face " + std::to_string(f) + ": vertex index " + std::to_string(k) +
                                    (t.empty() ? " is missing" : " is not an integer: '" + std::string(t) + "'"));
      checkFaceIndex(path, f, index, declared.vertices);
    }
    in.skipLine();  // face colour
  }
  return declared;
}

// ---- PLY -----------------------------------------------------------------------------------------

struct PlyProperty {
  std::string name;
  int size = 0;           // scalar size, or the list's element size
  int countSize = 0;      // list count size; 0 for a scalar
  bool isFloat = false, isSigned = false;
  bool countSigned = false;
};
struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

bool plyType(std::string_view t, int& size, bool& isFloat, bool& isSigned) {
  static const struct {
    const char* a;
    const char* b;
    int size;
    bool f, s;
  } types[] = {{"char", "int8", 1, false, true},     {"uchar", "uint8", 1, false, false},
               {"short", "int16", 2, false, true},   {"ushort", "uint16", 2, false, false},
               {"int", "int32", 4, false, true},     {"uint", "uint32", 4, false, false},
               {"float", "float32", 4, true, true},  {"double", "float64", 8, true, true}};
  for (const auto& x : types)
    if (t == x.a || t == x.b) {
      size = x.size;
      isFloat = x.f;
      isSigned = x.s;
      return true;
    }
  return false;
}

// Reads one binary value of a PLY type as a double (exact for every integer type).
double readBinary(const uint8_t* p, int size, bool isFloat, bool isSigned, bool bigEndian) {
  uint8_t b[8];
  std::memcpy(b, p, std::size_t(size));
  if (bigEndian) std::reverse(b, b + size);
  switch (size) {
    case 1: return isSigned ? double(int8_t(b[0])) : double(b[0]);
    case 2: { uint16_t v; std::memcpy(&v, b, 2); return isSigned ? double(int16_t(v)) : double(v); }
    case 4: {
      uint32_t v;
      std::memcpy(&v, b, 4);
      if (isFloat) return double(std::bit_cast<float>(v));
      return isSigned ? double(int32_t(v)) : double(v);
    }
    default: { uint64_t v; std::memcpy(&v, b, 8); return std::bit_cast<double>(v); }
  }
}

DeclaredMesh checkPly(const std::string& path, std::span<const uint8_t> bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  // The header ends at the first line that is end_header alone: OpenMesh reads the header word by
  // word and, when end_header is glued to other text, loops forever at the end of the file.
  std::size_t headerEnd = std::string_view::npos;
  for (std::size_t at = text.find("\nend_header"); at != std::string_view::npos; at = text.find("\nend_header", at + 1)) {
    std::size_t after = at + 11;
    while (after < text.size() && (text[after] == ' ' || text[after] == '\t' || text[after] == '\r')) ++after;
    if (after == text.size() || text[after] == '\n') {
      headerEnd = at + 1;
      break;
    }
  }
  if (text.substr(0, 3) != "ply" || text.size() < 4 || (text[3] != '\n' && text[3] != '\r') ||
      headerEnd == std::string_view::npos)
    throw tsah::FileError(path, "not a PLY file (no 'ply' line ... 'end_header' line)");
  std::size_t bodyStart = text.find('\n', headerEnd);
  bodyStart = bodyStart == std::string_view::npos ? bytes.size() : bodyStart + 1;

  enum class Format { Ascii, Little, Big } format = Format::Ascii;
  std::vector<PlyElement> elements;
  Tokens header(bytes.first(headerEnd), 3);
  // Each statement is one line with exactly its words: OpenMesh reads the header word by word, so a
  // missing word makes it take the next line's (at worst end_header) and loop forever at the end.
  for (std::string_view word = header.next(); !word.empty(); word = header.next()) {
    if (word == "comment" || word == "obj_info") {
      header.skipLine();
      continue;
    }
    if (word == "format") {
      const std::string_view f = header.nextOnLine();
      format = f == "ascii" ? Format::Ascii : f == "binary_little_endian" ? Format::Little
             : f == "binary_big_endian" ? Format::Big : throw tsah::FileError(path, "unknown PLY format '" + std::string(f) + "'");
      const std::string_view version = header.nextOnLine();
      double v = 0;
      if (!parseNumber(version, v) || v != 1.0)
        throw tsah::FileError(path, "unsupported PLY version '" + std::string(version) + "' (1.0 expected)");
    } else if (word == "element") {
      PlyElement e;
      e.name = std::string(header.nextOnLine());
      if (!parseCount(header.nextOnLine(), e.count)) throw tsah::FileError(path, "element " + e.name + " has no valid count");
      elements.push_back(std::move(e));
    } else if (word == "property") {
      if (elements.empty()) throw tsah::FileError(path, "property before any element");
      PlyProperty p;
      std::string_view t = header.nextOnLine();
      if (t == "list") {
        bool f;
        if (!plyType(header.nextOnLine(), p.countSize, f, p.countSigned) || f)
          throw tsah::FileError(path, "bad list count type in the header");
        t = header.nextOnLine();
      }
      if (!plyType(t, p.size, p.isFloat, p.isSigned)) throw tsah::FileError(path, "unknown property type '" + std::string(t) + "'");
      p.name = std::string(header.nextOnLine());
      if (p.name.empty()) throw tsah::FileError(path, "a property of element " + elements.back().name + " has no name");
      elements.back().properties.push_back(std::move(p));
    } else {
      throw tsah::FileError(path, "unexpected header word '" + std::string(word) + "'");
    }
    if (const std::string_view extra = header.nextOnLine(); !extra.empty())
      throw tsah::FileError(path, "unexpected header word '" + std::string(extra) + "' after the " + std::string(word) + " statement");
  }
  DeclaredMesh declared{true, 0, 0};
  uint64_t minBytes[2] = {0, 0};  // per vertex, per face
  for (const PlyElement& e : elements) {
    uint64_t record = 0;
    for (const PlyProperty& p : e.properties)
      record += format == Format::Ascii ? 2 : uint64_t(p.countSize ? p.countSize : p.size);
    if (e.name == "vertex") declared.vertices = e.count, minBytes[0] = record;
    if (e.name == "face") declared.faces = e.count, minBytes[1] = record;
  }
  checkCounts(path, declared.vertices, declared.faces, minBytes[0], minBytes[1], bytes.size() - bodyStart);

  const bool bigEndian = format == Format::Big;
  Tokens ascii(bytes, bodyStart);
  std::size_t offset = bodyStart;
  // The next value of `elementName` record `record`, as text or binary.
  auto value = [&](const std::string& elementName, uint64_t record, int size, bool isFloat, bool isSigned,
                   const std::string& what) -> double {
    const std::string where = elementName + " " + std::to_string(record) + ": " + what;
    if (format == Format::Ascii) {
      const std::string_view token = ascii.next();
      double v = 0;
      if (!parseNumber(token, v))
        throw tsah::FileError(path, where + (token.empty() ? " is missing (the file ends early)"
                                                       : " is not a number: '" + std::string(token) + "'"));
      return v;
    }
    if (bytes.size() - offset < std::size_t(size))
      throw tsah::FileError(path, where + " is missing (the file ends at byte " + std::to_string(bytes.size()) + ")");
    const double v = readBinary(bytes.data() + offset, size, isFloat, isSigned, bigEndian);
    offset += std::size_t(size);
    return v;
  };
  for (const PlyElement& e : elements) {
    const bool isVertex = e.name == "vertex", isFace = e.name == "face";
    for (uint64_t r = 0; r < e.count; ++r)
      for (const PlyProperty& p : e.properties) {
        if (!p.countSize) {
          const double v = value(e.name, r, p.size, p.isFloat, p.isSigned, "property " + p.name);
          if (isVertex && (p.name == "x" || p.name == "y" || p.name == "z")) checkCoordinate(path, r, v);
          continue;
        }
        const double n = value(e.name, r, p.countSize, false, p.countSigned, "list length of " + p.name);
        const bool indices = isFace && (p.name == "vertex_indices" || p.name == "vertex_index");
        // A count type holds at most 2^32 - 1, but ASCII text can say anything (2e21 does not convert).
        if (!(n >= 0) || n != std::floor(n) || n > 4294967295.0) {
          char number[32];
          std::snprintf(number, sizeof number, "%g", n);
          throw tsah::FileError(path, e.name + " " + std::to_string(r) + ": bad list length " + number);
        }
        if (indices) checkFaceSize(path, r, uint64_t(n));
        if (format != Format::Ascii && !indices) {  // skip the list without reading each value
          uint64_t skip = 0;
          if (__builtin_mul_overflow(uint64_t(n), uint64_t(p.size), &skip) || skip > bytes.size() - offset)
            throw tsah::FileError(path, e.name + " " + std::to_string(r) + ": list " + p.name + " runs past the end of the file");
          offset += std::size_t(skip);
          continue;
        }
        for (uint64_t k = 0; k < uint64_t(n); ++k) {
          const double v = value(e.name, r, p.size, p.isFloat, p.isSigned, p.name + " entry " + std::to_string(k));
          if (indices) checkFaceIndex(path, r, v >= -1e18 && v <= 1e18 && v == std::floor(v) ? int64_t(v) : -1, declared.vertices);
        }
      }
  }
  return declared;
}

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

DeclaredMesh checkMeshFile(const std::string& path, std::span<const uint8_t> bytes) {
  const std::string ext = lowerExtension(path);
  if (ext == ".off") return checkOff(path, bytes);
  if (ext == ".ply") return checkPly(path, bytes);
  return {};
}

}  // namespace anim
