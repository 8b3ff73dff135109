// The AFF parser: text -> bart_detail::ParsedScene. Every problem throws tsah::FileError naming the file
// and the line; sizes read from the text are checked against the input left before anything is
// reserved, includes are bounded in depth and cycles are refused.
// Longer than the project's ~600 lines on purpose: it is the whole grammar of one format (every
// AFF directive with its checks) over one tokenizer; split, each half would need the other's state.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>
#include <system_error>
#include <unordered_map>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "bart_scene.hpp"

namespace anim::bart_detail {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr uint32_t kMaxBlockNesting = 256;               // `{` depth within one file
constexpr uint64_t kMaxExpandedBlocks = uint64_t(1) << 22;  // transform instances after includes
constexpr uint64_t kMaxExpandedVertices = uint64_t(1) << 31;
constexpr std::size_t kMaxFileBytes = std::size_t(1) << 30;

uint64_t saturatingAdd(uint64_t a, uint64_t b) {
  return a > std::numeric_limits<uint64_t>::max() - b ? std::numeric_limits<uint64_t>::max() : a + b;
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

// Splits AFF text into whitespace-separated tokens; `{` and `}` are tokens of their own even when
// glued to a word, and `#` or `%` at the start of a token comments out the rest of the line.
class Tokens {
 public:
  Tokens(std::string_view text, std::string file) : text_(text), file_(std::move(file)) {}

  const std::string& file() const { return file_; }
  uint32_t line() const { return tokenLine_; }
  std::size_t remainingBytes() const { return text_.size() - pos_; }

  std::string_view peek() {
    if (!peeked_) {
      peekedToken_ = scan(peekedLine_);
      peeked_ = true;
    }
    return peekedToken_;
  }
  std::string_view next() {
    peek();
    peeked_ = false;
    tokenLine_ = peekedLine_;
    return peekedToken_;
  }
  bool atEnd() { return peek().empty(); }

  [[noreturn]] void fail(const std::string& what) const {
    throw tsah::FileError(file_, "line " + std::to_string(tokenLine_) + ": " + what);
  }

  std::string_view word(const char* what) {
    const std::string_view t = next();
    if (t.empty()) fail(std::string("unexpected end of file, expected ") + what);
    if (t == "{" || t == "}") fail(std::string("expected ") + what + ", found '" + std::string(t) + "'");
    return t;
  }
  void expect(std::string_view s, const char* context) {
    const std::string_view t = next();
    if (t != s)
      fail("expected '" + std::string(s) + "' " + context + ", found " +
           (t.empty() ? std::string("end of file") : "'" + std::string(t) + "'"));
  }

  static bool parseNumber(std::string_view t, double& value) {
    if (!t.empty() && t.front() == '+') t.remove_prefix(1);
    if (t.empty()) return false;
    const auto r = std::from_chars(t.data(), t.data() + t.size(), value);
    return r.ec == std::errc() && r.ptr == t.data() + t.size() && std::isfinite(value);
  }
  bool peekIsNumber() {
    double v;
    return parseNumber(peek(), v);
  }
  double number(const char* what) {
    const std::string_view t = next();
    double v = 0.0;
    if (t.empty()) fail(std::string("unexpected end of file, expected ") + what);
    if (!parseNumber(t, v)) fail(std::string("expected ") + what + " (a finite number), found '" + clip(t) + "'");
    return v;
  }
  template <std::size_t N>
  std::array<double, N> numbers(const char* what) {
    std::array<double, N> a;
    for (auto& v : a) v = number(what);
    return a;
  }
  int64_t integer(const char* what, int64_t lo, int64_t hi) {
    const std::string_view t = next();
    if (t.empty()) fail(std::string("unexpected end of file, expected ") + what);
    std::string_view s = t;
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    int64_t v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
      fail(std::string("expected ") + what + " (an integer), found '" + clip(t) + "'");
    if (v < lo || v > hi)
      fail(std::string(what) + " " + std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
           std::to_string(hi) + "]");
    return v;
  }
  // A count of items that each take at least `tokensPerItem` tokens: refused when the rest of the
  // input cannot hold them, so no hostile count reaches an allocation.
  std::size_t count(const char* what, std::size_t tokensPerItem, int64_t minimum = 0) {
    const int64_t n = integer(what, minimum, std::numeric_limits<int32_t>::max());
    const std::size_t fits = remainingBytes() / (2 * std::max<std::size_t>(tokensPerItem, 1)) + 1;
    if (std::size_t(n) > fits)
      fail(std::string(what) + " " + std::to_string(n) + " is more than the rest of the file can hold");
    return std::size_t(n);
  }

  static std::string clip(std::string_view t) {
    return t.size() > 40 ? std::string(t.substr(0, 40)) + "..." : std::string(t);
  }

 private:
  std::string_view scan(uint32_t& tokenLine) {
    for (;;) {
      while (pos_ < text_.size() && isSpace(text_[pos_])) {
        if (text_[pos_] == '\n') ++line_;
        ++pos_;
      }
      if (pos_ >= text_.size()) {
        tokenLine = line_;
        return {};
      }
      const char c = text_[pos_];
      if (c == '#' || c == '%') {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
        continue;
      }
      tokenLine = line_;
      const std::size_t start = pos_;
      if (c == '{' || c == '}') {
        ++pos_;
        return text_.substr(start, 1);
      }
      while (pos_ < text_.size() && !isSpace(text_[pos_]) && text_[pos_] != '{' && text_[pos_] != '}') ++pos_;
      return text_.substr(start, pos_ - start);
    }
  }

  std::string_view text_;
  std::string file_;
  std::size_t pos_ = 0;
  uint32_t line_ = 1;
  uint32_t tokenLine_ = 1;
  bool peeked_ = false;
  std::string_view peekedToken_;
  uint32_t peekedLine_ = 1;
};

// ---- small vector helpers -------------------------------------------------------------------------

using V3 = std::array<double, 3>;
V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double length(const V3& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

void addVertex(Geometry& g, const V3& p) {
  g.positions.push_back(static_cast<float>(p[0]));
  g.positions.push_back(static_cast<float>(p[1]));
  g.positions.push_back(static_cast<float>(p[2]));
}
void addTriangle(Geometry& g, uint32_t a, uint32_t b, uint32_t c) {
  g.indices.push_back(a);
  g.indices.push_back(b);
  g.indices.push_back(c);
}

// Merges vertices of one block at exactly the same position: they share the block's transform, so
// they stay together in every frame (AFF meshes and polygons repeat shared corners).
void weldVertices(Geometry& g) {
  struct KeyHash {
    std::size_t operator()(const std::array<uint32_t, 3>& k) const {
      return std::size_t((uint64_t(k[0]) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(k[1]) * 0xC2B2AE3D27D4EB4Full) ^ k[2]);
    }
  };
  std::unordered_map<std::array<uint32_t, 3>, uint32_t, KeyHash> seen;
  seen.reserve(g.vertexCount());
  std::vector<uint32_t> remap(g.vertexCount());
  std::vector<float> kept;
  kept.reserve(g.positions.size());
  for (uint32_t v = 0; v < g.vertexCount(); ++v) {
    std::array<uint32_t, 3> key;
    for (int a = 0; a < 3; ++a) {
      const float x = g.positions[3 * v + a] + 0.0f;  // -0 and +0 are one position
      std::memcpy(&key[a], &x, 4);
    }
    const auto [it, inserted] = seen.emplace(key, uint32_t(kept.size() / 3));
    if (inserted) kept.insert(kept.end(), g.positions.begin() + 3 * v, g.positions.begin() + 3 * v + 3);
    remap[v] = it->second;
  }
  if (kept.size() == g.positions.size()) return;
  for (uint32_t& i : g.indices) i = remap[i];
  g.positions = std::move(kept);
}

// T * R * S of a static transform: scale, then rotate `degrees` about `axis`, then translate.
Affine staticTransform(const V3& scale, const V3& axis, double degrees, const V3& translation, Tokens& tokens) {
  const double len = length(axis);
  double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const double turns = degrees / 360.0;
  if (turns != std::round(turns)) {
    if (!(len > 0.0)) tokens.fail("static transform rotates about a zero axis");
    const double x = axis[0] / len, y = axis[1] / len, z = axis[2] / len;
    const double a = degrees * kPi / 180.0, c = std::cos(a), s = std::sin(a), t = 1.0 - c;
    const double m[9] = {t * x * x + c,     t * x * y - s * z, t * x * z + s * y,  //
                         t * x * y + s * z, t * y * y + c,     t * y * z - s * x,  //
                         t * x * z - s * y, t * y * z + s * x, t * z * z + c};
    std::copy(m, m + 9, r);
  }
  Affine out;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) out[4 * row + col] = r[3 * row + col] * scale[col];
    out[4 * row + 3] = translation[row];
  }
  return out;
}

// Builds an orthonormal pair (u, v) perpendicular to the unit vector d.
void perpendicularFrame(const V3& d, V3& u, V3& v) {
  const V3 helper = std::fabs(d[0]) < 0.9 ? V3{1, 0, 0} : V3{0, 1, 0};
  u = cross(d, helper);
  const double l = length(u);
  u = {u[0] / l, u[1] / l, u[2] / l};
  v = cross(d, u);
}

class Parser {
 public:
  Parser(const BartOptions& options, ParsedScene& scene, std::string rootDir)
      : options_(options), scene_(scene), rootDir_(std::move(rootDir)) {}

  std::shared_ptr<const FileScene> parseFile(std::string_view text, const std::string& path) {
    auto fileScene = std::make_shared<FileScene>();
    fileScene->path = path;
    Tokens tokens(text, path);
    std::vector<Block*> stack{&fileScene->root};
    fileScene->root.file = path;
    fileScene->root.line = 1;
    while (!tokens.atEnd()) command(tokens, stack);
    if (stack.size() > 1)
      throw tsah::FileError(path, "line " + std::to_string(stack.back()->line) + ": '{' is never closed");
    closeBlock(fileScene->root, tokens);
    return fileScene;
  }

 private:
  struct CacheEntry {
    std::shared_ptr<const FileScene> scene;
    int64_t detailAfter;
  };

  void command(Tokens& tk, std::vector<Block*>& stack) {
    const std::string_view cmd = tk.next();
    Block& block = *stack.back();
    if (cmd == "}") {
      if (stack.size() == 1) tk.fail("'}' without a matching '{'");
      closeBlock(block, tk);
      stack.pop_back();
    } else if (cmd == "{") {
      tk.fail("'{' without a transform before it");
    } else if (cmd == "m") {
      mesh(tk, block.geometry);
    } else if (cmd == "p" || cmd == "pp") {
      polygon(tk, block.geometry, cmd == "pp");
    } else if (cmd == "tt" || cmd == "ttp") {
      texturedTriangle(tk, block.geometry, cmd == "ttp");
    } else if (cmd == "tpa") {
      animatedTriangle(tk, block);
    } else if (cmd == "c") {
      cone(tk, block.geometry);
    } else if (cmd == "s") {
      sphere(tk, block.geometry);
    } else if (cmd == "xs" || cmd == "x") {
      auto child = std::make_unique<Block>();
      child->file = tk.file();
      child->line = tk.line();
      if (cmd == "xs") {
        const auto scale = tk.numbers<3>("scale");
        const auto axis = tk.numbers<3>("rotation axis");
        const double degrees = tk.number("rotation angle");
        const auto translation = tk.numbers<3>("translation");
        child->kind = Block::Kind::Static;
        child->matrix = staticTransform(scale, axis, degrees, translation, tk);
      } else {
        child->kind = Block::Kind::Animated;
        child->name = std::string(tk.word("transform name"));
      }
      tk.expect("{", "after the transform");
      if (stack.size() >= kMaxBlockNesting) tk.fail("transforms nested deeper than " + std::to_string(kMaxBlockNesting));
      Block* raw = child.get();
      block.children.push_back({std::move(child), nullptr});
      stack.push_back(raw);
    } else if (cmd == "i") {
      include(tk, block);
    } else if (cmd == "d") {
      detail_ = tk.integer("detail level", std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max());
    } else if (cmd == "k") {
      keyBlock(tk);
    } else if (cmd == "a") {
      AnimationRange r;
      r.file = tk.file();
      r.line = tk.line();
      r.t0 = tk.number("animation start time");
      r.t1 = tk.number("animation end time");
      r.frames = tk.integer("frame count", 1, std::numeric_limits<int32_t>::max());
      if (r.frames > 1 && !(r.t1 > r.t0)) tk.fail("animation end time must be after the start time");
      scene_.range = r;
    } else if (cmd == "v") {
      view(tk);
    } else if (cmd == "l" || cmd == "la") {
      if (cmd == "la") tk.word("light name");
      tk.numbers<3>("light position");
      for (int i = 0; i < 3 && tk.peekIsNumber(); ++i) tk.number("light colour");
      ++scene_.lights;
    } else if (cmd == "b") {
      tk.numbers<3>("background colour");
      ++scene_.backgrounds;
    } else if (cmd == "am") {
      tk.numbers<3>("ambient light colour");
      ++scene_.lights;
    } else if (cmd == "f") {
      tk.numbers<8>("material parameter");
      ++scene_.materials;
    } else if (cmd == "fm") {
      tk.numbers<12>("material parameter");
      ++scene_.materials;
    } else {
      tk.fail("unknown command '" + Tokens::clip(cmd) + "'");
    }
  }

  void closeBlock(Block& b, Tokens& tk) {
    weldVertices(b.geometry);
    uint64_t vertices = b.geometry.vertexCount(), triangles = b.geometry.indices.size() / 3, blocks = 1;
    vertices = saturatingAdd(vertices, 3 * uint64_t(b.animated.size()));
    triangles = saturatingAdd(triangles, b.animated.size());
    for (const Block::Child& c : b.children) {
      const Block& sub = c.block ? *c.block : c.include->root;
      vertices = saturatingAdd(vertices, sub.totalVertices);
      triangles = saturatingAdd(triangles, sub.totalTriangles);
      blocks = saturatingAdd(blocks, sub.totalBlocks);
    }
    if (blocks > kMaxExpandedBlocks)
      tk.fail("the scene expands to more than " + std::to_string(kMaxExpandedBlocks) +
              " transform instances through its includes");
    if (vertices > kMaxExpandedVertices)
      tk.fail("the scene expands to more than " + std::to_string(kMaxExpandedVertices) + " vertices");
    b.totalVertices = vertices;
    b.totalTriangles = triangles;
    b.totalBlocks = blocks;
  }

  void mesh(Tokens& tk, Geometry& g) {
    tk.expect("vertices", "after 'm'");
    const std::size_t nv = tk.count("vertex count", 3);
    std::vector<float> local;
    local.reserve(nv * 3);
    for (std::size_t i = 0; i < 3 * nv; ++i) local.push_back(static_cast<float>(tk.number("vertex coordinate")));
    bool normals = false, texcoords = false;
    std::string_view section = tk.word("'normals', 'texturecoords' or 'triangles'");
    if (section == "normals") {
      normals = true;
      const std::size_t n = tk.count("normal count", 3);
      for (std::size_t i = 0; i < 3 * n; ++i) tk.number("normal coordinate");
      section = tk.word("'texturecoords' or 'triangles'");
    }
    if (section == "texturecoords") {
      texcoords = true;
      const std::size_t n = tk.count("texture coordinate count", 2);
      // The texture file name is optional in practice: a number here is already a coordinate.
      if (!tk.peekIsNumber()) {
        tk.word("texture file name");
        ++scene_.textures;
      }
      for (std::size_t i = 0; i < 2 * n; ++i) tk.number("texture coordinate");
      section = tk.word("'triangles'");
    }
    if (section != "triangles") tk.fail("expected 'triangles' in mesh, found '" + Tokens::clip(section) + "'");
    const std::size_t perTriangle = 3 + (normals ? 3 : 0) + (texcoords ? 3 : 0);
    const std::size_t nt = tk.count("triangle count", perTriangle);
    // Only the vertices the triangles use are kept, renumbered in order of first use.
    constexpr uint32_t kUnused = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> remap(nv, kUnused);
    g.indices.reserve(g.indices.size() + 3 * nt);
    for (std::size_t t = 0; t < nt; ++t) {
      for (int c = 0; c < 3; ++c) {
        const int64_t v = tk.integer("vertex index", 0, std::numeric_limits<int32_t>::max());
        if (std::size_t(v) >= nv)
          tk.fail("triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) + " but the mesh has " +
                  std::to_string(nv) + " vertices");
        if (remap[v] == kUnused) {
          remap[v] = g.vertexCount();
          g.positions.insert(g.positions.end(), local.begin() + 3 * v, local.begin() + 3 * v + 3);
        }
        g.indices.push_back(remap[v]);
      }
      for (std::size_t k = 3; k < perTriangle; ++k) tk.integer("normal or texture index", 0, std::numeric_limits<int32_t>::max());
    }
  }

  void polygon(Tokens& tk, Geometry& g, bool withNormals) {
    const std::size_t n = tk.count("polygon vertex count", withNormals ? 6 : 3, 3);
    const uint32_t first = g.vertexCount();
    for (std::size_t i = 0; i < n; ++i) {
      addVertex(g, tk.numbers<3>("polygon vertex coordinate"));
      if (withNormals) tk.numbers<3>("polygon normal coordinate");
    }
    for (uint32_t i = 1; i + 1 < n; ++i) addTriangle(g, first, first + i, first + i + 1);
  }

  void texturedTriangle(Tokens& tk, Geometry& g, bool withNormals) {
    tk.word("texture name");
    ++scene_.textures;
    const uint32_t first = g.vertexCount();
    for (int c = 0; c < 3; ++c) {
      addVertex(g, tk.numbers<3>("triangle vertex coordinate"));
      if (withNormals) tk.numbers<3>("triangle normal coordinate");
      tk.numbers<2>("texture coordinate");
    }
    addTriangle(g, first, first + 1, first + 2);
  }

  void animatedTriangle(Tokens& tk, Block& block) {
    const std::size_t n = tk.count("animated triangle key count", 19, 1);
    AnimatedTriangle tri;
    tri.times.reserve(n);
    tri.corners.reserve(9 * n);
    for (std::size_t k = 0; k < n; ++k) {
      const double t = tk.number("key shape time");
      if (!tri.times.empty() && t < tri.times.back()) tk.fail("animated triangle key times decrease");
      tri.times.push_back(t);
      for (int c = 0; c < 3; ++c) {
        for (double v : tk.numbers<3>("animated triangle vertex coordinate")) tri.corners.push_back(static_cast<float>(v));
        tk.numbers<3>("animated triangle normal coordinate");
      }
    }
    block.animated.push_back(std::move(tri));
  }

  uint32_t segments() const { return std::max<uint32_t>(3, std::min<uint32_t>(options_.tessellation, 4096)); }

  // An open cone or cylinder (NFF draws no end caps): a ring at the base and one at the apex, or a
  // single apex vertex when the apex radius is zero.
  void cone(Tokens& tk, Geometry& g) {
    const V3 base = tk.numbers<3>("cone base");
    double r0 = tk.number("cone base radius");
    const V3 apex = tk.numbers<3>("cone apex");
    double r1 = tk.number("cone apex radius");
    r0 = std::fabs(r0);  // negative radii only mean "visible from inside"
    r1 = std::fabs(r1);
    const V3 axis = sub(apex, base);
    const double len = length(axis);
    if (!(len > 0.0)) tk.fail("cone base and apex coincide");
    if (r0 == 0.0 && r1 == 0.0) tk.fail("cone has two zero radii");
    if (r0 == 0.0) return cone2(g, apex, r1, base, 0.0, axis, len);
    cone2(g, base, r0, apex, r1, axis, len);
  }
  void cone2(Geometry& g, const V3& base, double r0, const V3& apex, double r1, const V3& axis, double len) {
    const V3 d{axis[0] / len, axis[1] / len, axis[2] / len};
    V3 u, v;
    perpendicularFrame(d, u, v);
    const uint32_t s = segments();
    const uint32_t first = g.vertexCount();
    auto ring = [&](const V3& c, double r) {
      for (uint32_t k = 0; k < s; ++k) {
        const double a = 2.0 * kPi * k / s, ca = std::cos(a) * r, sa = std::sin(a) * r;
        addVertex(g, {c[0] + ca * u[0] + sa * v[0], c[1] + ca * u[1] + sa * v[1], c[2] + ca * u[2] + sa * v[2]});
      }
    };
    ring(base, r0);
    if (r1 > 0.0) {
      ring(apex, r1);
      for (uint32_t k = 0; k < s; ++k) {
        const uint32_t k1 = (k + 1) % s;
        addTriangle(g, first + k, first + k1, first + s + k1);
        addTriangle(g, first + k, first + s + k1, first + s + k);
      }
    } else {
      addVertex(g, apex);
      for (uint32_t k = 0; k < s; ++k) addTriangle(g, first + k, first + (k + 1) % s, first + s);
    }
  }

  void sphere(Tokens& tk, Geometry& g) {
    const V3 c = tk.numbers<3>("sphere centre");
    const double r = std::fabs(tk.number("sphere radius"));
    if (!(r > 0.0)) tk.fail("sphere radius is zero");
    const uint32_t slices = segments(), stacks = std::max<uint32_t>(2, slices / 2);
    const uint32_t first = g.vertexCount();
    addVertex(g, {c[0], c[1] + r, c[2]});
    for (uint32_t i = 1; i < stacks; ++i) {
      const double phi = kPi * i / stacks;
      for (uint32_t k = 0; k < slices; ++k) {
        const double theta = 2.0 * kPi * k / slices;
        addVertex(g, {c[0] + r * std::sin(phi) * std::cos(theta), c[1] + r * std::cos(phi),
                      c[2] + r * std::sin(phi) * std::sin(theta)});
      }
    }
    addVertex(g, {c[0], c[1] - r, c[2]});
    const uint32_t south = g.vertexCount() - 1;
    auto at = [&](uint32_t ring, uint32_t k) { return first + 1 + (ring - 1) * slices + k % slices; };
    for (uint32_t k = 0; k < slices; ++k) addTriangle(g, first, at(1, k + 1), at(1, k));
    for (uint32_t i = 1; i + 1 < stacks; ++i)
      for (uint32_t k = 0; k < slices; ++k) {
        addTriangle(g, at(i, k), at(i, k + 1), at(i + 1, k + 1));
        addTriangle(g, at(i, k), at(i + 1, k + 1), at(i + 1, k));
      }
    for (uint32_t k = 0; k < slices; ++k) addTriangle(g, south, at(stacks - 1, k), at(stacks - 1, k + 1));
  }

  void view(Tokens& tk) {
    View v = scene_.view.value_or(View{});
    for (;;) {
      const std::string_view key = tk.peek();
      if (key == "from") {
        tk.next();
        v.from = tk.numbers<3>("view 'from' coordinate");
      } else if (key == "at") {
        tk.next();
        v.at = tk.numbers<3>("view 'at' coordinate");
      } else if (key == "up") {
        tk.next();
        v.up = tk.numbers<3>("view 'up' coordinate");
      } else if (key == "angle") {
        tk.next();
        v.angle = tk.number("view angle");
      } else if (key == "hither") {
        tk.next();
        tk.number("hither distance");
      } else if (key == "resolution") {
        tk.next();
        tk.integer("horizontal resolution", 0, std::numeric_limits<int32_t>::max());
        tk.integer("vertical resolution", 0, std::numeric_limits<int32_t>::max());
      } else {
        break;
      }
    }
    scene_.view = v;
  }

  void keyBlock(Tokens& tk) {
    KeyBlock kb;
    kb.file = tk.file();
    kb.line = tk.line();
    kb.name = std::string(tk.word("animation name"));
    tk.expect("{", "after the animation name");
    for (;;) {
      const std::string_view motion = tk.next();
      if (motion == "}") break;
      if (motion.empty()) tk.fail("unexpected end of file in the keys of '" + kb.name + "'");
      const uint32_t motionLine = tk.line();
      auto spline = [&](auto make) {
        try {
          return make();
        } catch (const tsah::FileError&) {
          throw;
        } catch (const tsah::Error& e) {
          throw tsah::FileError(tk.file(), "line " + std::to_string(motionLine) + ": " + e.what());
        }
      };
      if (motion == "transl" || motion == "scale") {
        const bool isScale = motion == "scale";
        if (isScale ? kb.scale.has_value() : kb.translation.has_value())
          tk.fail("'" + std::string(motion) + "' appears twice in the keys of '" + kb.name + "'");
        const std::size_t n = tk.count("key count", 7, 4);
        std::vector<bart::SplineKey> keys(n);
        for (auto& k : keys) {
          k.time = tk.number("key time");
          k.value = tk.numbers<3>(isScale ? "scale" : "translation");
          k.tension = tk.number("tension");
          k.continuity = tk.number("continuity");
          k.bias = tk.number("bias");
        }
        auto& target = isScale ? kb.scale : kb.translation;
        target = spline([&] { return bart::PositionSpline(keys); });
      } else if (motion == "rot") {
        if (kb.rotation) tk.fail("'rot' appears twice in the keys of '" + kb.name + "'");
        const std::size_t n = tk.count("key count", 8, 4);
        std::vector<bart::RotationKey> keys(n);
        for (auto& k : keys) {
          k.time = tk.number("key time");
          k.axis = tk.numbers<3>("rotation axis");
          k.angleDegrees = tk.number("rotation angle");
          k.tension = tk.number("tension");
          k.continuity = tk.number("continuity");
          k.bias = tk.number("bias");
        }
        kb.rotation = spline([&] { return bart::RotationSpline(keys); });
      } else if (motion == "visibility") {
        const std::size_t n = tk.count("key count", 2, 1);
        for (std::size_t i = 0; i < n; ++i) {
          const double t = tk.number("visibility time");
          const int64_t flag = tk.integer("visibility flag", 0, 1);
          kb.visibility.emplace_back(t, flag != 0);
        }
      } else {
        tk.fail("unknown key type '" + Tokens::clip(motion) + "' (expected transl, rot, scale or visibility)");
      }
    }
    scene_.keys[kb.name] = std::move(kb);
  }

  void include(Tokens& tk, Block& block) {
    namespace fs = std::filesystem;
    const int64_t level = tk.integer("include detail level", std::numeric_limits<int32_t>::min(),
                                     std::numeric_limits<int32_t>::max());
    const std::string name(tk.word("include file name"));
    if (level > detail_) return;  // more detail than the scene asks for
    std::error_code ec;
    fs::path target = fs::path(tk.file()).parent_path() / name;
    if (!fs::is_regular_file(target, ec) && !rootDir_.empty() && fs::is_regular_file(fs::path(rootDir_) / name, ec))
      target = fs::path(rootDir_) / name;
    if (!fs::is_regular_file(target, ec)) tk.fail("cannot open include file '" + name + "'");
    fs::path canonical = fs::weakly_canonical(target, ec);
    if (ec) canonical = target.lexically_normal();
    const std::string key = canonical.string();
    if (std::find(includeStack_.begin(), includeStack_.end(), key) != includeStack_.end()) {
      std::string chain;
      for (const auto& p : includeStack_) chain += fs::path(p).filename().string() + " -> ";
      tk.fail("include cycle: " + chain + fs::path(key).filename().string());
    }
    if (includeStack_.size() >= options_.maxIncludeDepth)
      tk.fail("includes nested deeper than " + std::to_string(options_.maxIncludeDepth) + " levels");

    const auto cached = cache_.find({key, detail_});
    if (cached != cache_.end()) {
      block.children.push_back({nullptr, cached->second.scene});
      detail_ = cached->second.detailAfter;
      return;
    }
    const int64_t detailBefore = detail_;
    const std::vector<uint8_t> bytes = tsah::readFile(target.string(), kMaxFileBytes);
    includeStack_.push_back(key);
    auto sub = parseFile(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), target.string());
    includeStack_.pop_back();
    cache_[{key, detailBefore}] = CacheEntry{sub, detail_};
    block.children.push_back({nullptr, std::move(sub)});
  }

 public:
  void enterRoot(const std::string& canonicalPath) { includeStack_.push_back(canonicalPath); }

 private:
  const BartOptions& options_;
  ParsedScene& scene_;
  std::string rootDir_;
  int64_t detail_ = 0;
  std::vector<std::string> includeStack_;
  std::map<std::pair<std::string, int64_t>, CacheEntry> cache_;
};

}  // namespace

ParsedScene parseScene(std::string_view text, const std::string& path, const BartOptions& options) {
  namespace fs = std::filesystem;
  ParsedScene scene;
  std::error_code ec;
  const fs::path rootDir = fs::path(path).parent_path();
  Parser parser(options, scene, rootDir.string());
  fs::path canonical = fs::weakly_canonical(fs::path(path), ec);
  if (ec) canonical = fs::path(path).lexically_normal();
  parser.enterRoot(canonical.string());
  scene.root = parser.parseFile(text, path);
  return scene;
}

}  // namespace anim::bart_detail
