#include "anim/generators.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "tsah/base/error.hpp"

namespace anim {

namespace {

using V3 = std::array<float, 3>;
constexpr float kPi = std::numbers::pi_v<float>;

// splitmix64: a tiny PRNG whose sequence is the same on every platform and standard library.
class Random {
 public:
  explicit Random(uint64_t seed) : state_(seed) {}
  uint64_t next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float uniform(float lo = 0.0f, float hi = 1.0f) {
    return lo + (hi - lo) * float(double(next() >> 11) * 0x1.0p-53);
  }
  V3 unitVector() {
    const float z = uniform(-1.0f, 1.0f), phi = uniform(0.0f, 2.0f * kPi);
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    return {r * std::cos(phi), r * std::sin(phi), z};
  }

 private:
  uint64_t state_;
};

V3 add(V3 a, V3 b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
V3 sub(V3 a, V3 b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 scale(V3 a, float s) { return {a[0] * s, a[1] * s, a[2] * s}; }

// Rodrigues rotation of v about the unit axis by angle.
V3 rotate(V3 v, V3 axis, float angle) {
  const float c = std::cos(angle), s = std::sin(angle);
  const float d = axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2];
  const V3 x = {axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2],
                axis[0] * v[1] - axis[1] * v[0]};
  return {v[0] * c + x[0] * s + axis[0] * d * (1 - c), v[1] * c + x[1] * s + axis[1] * d * (1 - c),
          v[2] * c + x[2] * s + axis[2] * d * (1 - c)};
}

struct Mesh {
  std::vector<uint32_t> indices;
  std::vector<V3> vertices;
};

// A UV sphere of radius r around c with about `triangles` triangles (at least 8 segments).
Mesh uvSphere(uint32_t triangles, V3 c, float r) {
  // triangles = 2 * segments * (rings - 1) with rings = segments / 2.
  const uint32_t segments = std::max(8u, uint32_t(std::lround(std::sqrt(double(triangles) + 1.0) + 1.0)));
  const uint32_t rings = std::max(3u, segments / 2);
  Mesh m;
  m.vertices.push_back({c[0], c[1] + r, c[2]});  // north pole
  for (uint32_t i = 1; i < rings; ++i) {
    const float theta = kPi * float(i) / float(rings);
    for (uint32_t j = 0; j < segments; ++j) {
      const float phi = 2.0f * kPi * float(j) / float(segments);
      m.vertices.push_back({c[0] + r * std::sin(theta) * std::cos(phi), c[1] + r * std::cos(theta),
                            c[2] + r * std::sin(theta) * std::sin(phi)});
    }
  }
  const uint32_t south = uint32_t(m.vertices.size());
  m.vertices.push_back({c[0], c[1] - r, c[2]});
  auto ring = [&](uint32_t i, uint32_t j) { return 1 + (i - 1) * segments + (j % segments); };
  for (uint32_t j = 0; j < segments; ++j) m.indices.insert(m.indices.end(), {0, ring(1, j + 1), ring(1, j)});
  for (uint32_t i = 1; i + 1 < rings; ++i)
    for (uint32_t j = 0; j < segments; ++j) {
      const uint32_t a = ring(i, j), b = ring(i, j + 1), cc = ring(i + 1, j), d = ring(i + 1, j + 1);
      m.indices.insert(m.indices.end(), {a, b, d, a, d, cc});
    }
  for (uint32_t j = 0; j < segments; ++j)
    m.indices.insert(m.indices.end(), {south, ring(rings - 1, j), ring(rings - 1, j + 1)});
  return m;
}

Animation finish(const Mesh& base, uint32_t frames, const std::vector<float>& positions, const char* name) {
  std::vector<double> times(frames);
  for (uint32_t f = 0; f < frames; ++f) times[f] = double(f);
  return Animation(base.indices, uint32_t(base.vertices.size()), positions, std::move(times), name);
}

// A sphere broken into fragments (triangles grouped around random seed points). Each fragment owns
// its vertices so it can separate; after a short rest the fragments fly outwards under gravity and
// tumble, so the spatial grouping of frame 0 becomes useless later (the Dragon-Bunny case).
Animation explode(const GeneratorOptions& o) {
  Random rng(o.seed);
  const Mesh sphere = uvSphere(o.triangles, {0, 0, 0}, 1.0f);
  const uint32_t triCount = uint32_t(sphere.indices.size() / 3);
  const uint32_t fragments = std::clamp(triCount / 24, 2u, 400u);
  std::vector<V3> seeds(fragments);
  for (auto& s : seeds) s = rng.unitVector();
  // Assign each triangle to the nearest seed direction.
  std::vector<uint32_t> fragmentOf(triCount);
  for (uint32_t t = 0; t < triCount; ++t) {
    V3 c{0, 0, 0};
    for (int k = 0; k < 3; ++k) c = add(c, sphere.vertices[sphere.indices[3 * t + k]]);
    float best = -1e30f;
    for (uint32_t s = 0; s < fragments; ++s) {
      const float d = c[0] * seeds[s][0] + c[1] * seeds[s][1] + c[2] * seeds[s][2];
      if (d > best) best = d, fragmentOf[t] = s;
    }
  }
  // Unshare vertices between fragments: one copy per (fragment, original vertex).
  Mesh mesh;
  std::vector<uint32_t> vertexFragment;
  {
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> copies(sphere.vertices.size());
    for (uint32_t t = 0; t < triCount; ++t)
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = sphere.indices[3 * t + k], f = fragmentOf[t];
        auto& list = copies[v];
        auto it = std::find_if(list.begin(), list.end(), [&](auto& p) { return p.first == f; });
        if (it == list.end()) {
          list.emplace_back(f, uint32_t(mesh.vertices.size()));
          mesh.vertices.push_back(sphere.vertices[v]);
          vertexFragment.push_back(f);
          it = std::prev(list.end());
        }
        mesh.indices.push_back(it->second);
      }
  }
  struct Motion {
    V3 center{0, 0, 0}, velocity, axis;
    float spin;
    uint32_t count = 0;
  };
  std::vector<Motion> motion(fragments);
  for (uint32_t v = 0; v < mesh.vertices.size(); ++v) {
    auto& m = motion[vertexFragment[v]];
    m.center = add(m.center, mesh.vertices[v]);
    ++m.count;
  }
  for (auto& m : motion) {
    if (m.count) m.center = scale(m.center, 1.0f / float(m.count));
    const float len = std::sqrt(m.center[0] * m.center[0] + m.center[1] * m.center[1] + m.center[2] * m.center[2]);
    const V3 out = len > 0 ? scale(m.center, 1.0f / len) : rng.unitVector();
    m.velocity = add(scale(out, rng.uniform(2.0f, 6.0f)), scale(rng.unitVector(), 1.0f));
    m.velocity[1] += rng.uniform(1.0f, 3.0f);
    m.axis = rng.unitVector();
    m.spin = rng.uniform(-3.0f * kPi, 3.0f * kPi);
  }
  const uint32_t frames = std::max(1u, o.frames);
  std::vector<float> positions;
  positions.reserve(std::size_t(frames) * mesh.vertices.size() * 3);
  for (uint32_t f = 0; f < frames; ++f) {
    const float u = frames == 1 ? 0.0f : float(f) / float(frames - 1);
    const float t = std::max(0.0f, (u - 0.15f) / 0.85f);  // rest, then fly
    for (uint32_t v = 0; v < mesh.vertices.size(); ++v) {
      const Motion& m = motion[vertexFragment[v]];
      const V3 local = rotate(sub(mesh.vertices[v], m.center), m.axis, m.spin * t);
      V3 c = add(m.center, scale(m.velocity, t));
      c[1] -= 4.0f * t * t;  // gravity
      const V3 p = add(c, local);
      positions.insert(positions.end(), p.begin(), p.end());
    }
  }
  return finish(mesh, frames, positions, "explode");
}

// A square sheet (grid of quads, two triangles each) rippled by travelling waves with random
// directions and phases, plus a slow billow: a cloth-like deformation with constant topology.
Animation wave(const GeneratorOptions& o) {
  Random rng(o.seed);
  const uint32_t n = std::max(2u, uint32_t(std::lround(std::sqrt(double(o.triangles) / 2.0))));
  Mesh mesh;
  for (uint32_t i = 0; i <= n; ++i)
    for (uint32_t j = 0; j <= n; ++j) mesh.vertices.push_back({float(j) / float(n) * 2 - 1, 0, float(i) / float(n) * 2 - 1});
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t j = 0; j < n; ++j) {
      const uint32_t a = i * (n + 1) + j, b = a + 1, c = a + n + 1, d = c + 1;
      mesh.indices.insert(mesh.indices.end(), {a, c, b, b, c, d});
    }
  struct Wave {
    float kx, kz, omega, phase, amplitude;
  };
  std::array<Wave, 4> waves;
  for (auto& w : waves) {
    const float dir = rng.uniform(0, 2 * kPi), k = rng.uniform(2.0f, 7.0f);
    w = {k * std::cos(dir), k * std::sin(dir), rng.uniform(0.15f, 0.5f), rng.uniform(0, 2 * kPi), rng.uniform(0.03f, 0.12f)};
  }
  const uint32_t frames = std::max(1u, o.frames);
  std::vector<float> positions;
  positions.reserve(std::size_t(frames) * mesh.vertices.size() * 3);
  for (uint32_t f = 0; f < frames; ++f) {
    const float t = float(f);
    for (const V3& v : mesh.vertices) {
      float y = 0.0f;
      for (const Wave& w : waves) y += w.amplitude * std::sin(w.kx * v[0] + w.kz * v[2] - w.omega * t + w.phase);
      const float billow = 0.3f * std::sin(0.05f * t) * (1.0f - v[0] * v[0]) * (1.0f - v[2] * v[2]);
      // The sheet also folds: the far edge lifts and swings over time.
      const float lift = 0.4f * (v[2] + 1.0f) * (v[2] + 1.0f) * std::sin(0.03f * t + v[0]);
      positions.insert(positions.end(), {v[0], y + billow + lift, v[2] - 0.1f * lift});
    }
  }
  return finish(mesh, frames, positions, "wave");
}

// Two layers of small spheres that slide through each other in opposite directions. At frame 0
// every sphere of group A sits next to a partner of group B; as they pass, partners change, so a
// grouping built on frame 0 goes stale while "same group" stays a good grouping for all frames.
Animation swap(const GeneratorOptions& o) {
  Random rng(o.seed);
  const uint32_t perObject = 48;
  const uint32_t objects = std::max(2u, o.triangles / perObject) & ~1u;
  const uint32_t perGroup = objects / 2;
  const uint32_t columns = std::max(1u, uint32_t(std::lround(std::sqrt(double(perGroup)))));
  const uint32_t rows = (perGroup + columns - 1) / columns;
  const float spacing = 1.0f, radius = 0.3f;
  const float travel = spacing * float(columns);  // each group ends where the other began
  Mesh mesh;
  struct Object {
    V3 start, direction, axis;
    float spin;
    uint32_t firstVertex, vertexCount;
  };
  std::vector<Object> objs;
  for (uint32_t g = 0; g < 2; ++g)
    for (uint32_t k = 0; k < perGroup; ++k) {
      const float x = float(k % columns) * spacing + (g == 0 ? -travel : 0.0f);
      const float z = float(k / columns) * spacing + rng.uniform(-0.1f, 0.1f);
      const float y = (g == 0 ? 0.15f : -0.15f) + rng.uniform(-0.05f, 0.05f);
      const V3 c{x + (g == 0 ? spacing * 0.5f : 0.0f), y, z - float(rows) * spacing * 0.5f};
      const Mesh s = uvSphere(perObject, {0, 0, 0}, radius * rng.uniform(0.8f, 1.2f));
      const uint32_t base = uint32_t(mesh.vertices.size());
      for (uint32_t idx : s.indices) mesh.indices.push_back(base + idx);
      mesh.vertices.insert(mesh.vertices.end(), s.vertices.begin(), s.vertices.end());
      objs.push_back({c, {g == 0 ? 1.0f : -1.0f, 0, 0}, rng.unitVector(), rng.uniform(-kPi, kPi),
                      base, uint32_t(s.vertices.size())});
    }
  const uint32_t frames = std::max(1u, o.frames);
  std::vector<float> positions(std::size_t(frames) * mesh.vertices.size() * 3);
  for (uint32_t f = 0; f < frames; ++f) {
    const float u = frames == 1 ? 0.0f : float(f) / float(frames - 1);
    float* out = positions.data() + std::size_t(f) * mesh.vertices.size() * 3;
    for (const Object& ob : objs) {
      const V3 c = add(ob.start, scale(ob.direction, travel * u));
      for (uint32_t v = 0; v < ob.vertexCount; ++v) {
        const V3 p = add(c, rotate(mesh.vertices[ob.firstVertex + v], ob.axis, ob.spin * u));
        std::copy(p.begin(), p.end(), out + 3 * std::size_t(ob.firstVertex + v));
      }
    }
  }
  return finish(mesh, frames, positions, "swap");
}

}  // namespace

Animation generate(GeneratorKind kind, const GeneratorOptions& options) {
  if (options.triangles == 0 || options.triangles > 50'000'000u)
    throw tsah::ConfigError("generate: triangles must be between 1 and 50,000,000");
  if (options.frames == 0 || options.frames > 100'000u)
    throw tsah::ConfigError("generate: frames must be between 1 and 100,000");
  if (double(options.triangles) * options.frames > 5e8)
    throw tsah::ConfigError("generate: triangles x frames is too large (positions would not fit in memory)");
  switch (kind) {
    case GeneratorKind::Explode: return explode(options);
    case GeneratorKind::Wave: return wave(options);
    case GeneratorKind::Swap: return swap(options);
  }
  throw tsah::ConfigError("generate: unknown kind");
}

GeneratorKind parseGeneratorKind(std::string_view name) {
  if (name == "explode") return GeneratorKind::Explode;
  if (name == "wave") return GeneratorKind::Wave;
  if (name == "swap") return GeneratorKind::Swap;
  throw tsah::ConfigError("unknown generator '" + std::string(name) + "' (expected explode, wave or swap)");
}

const char* generatorName(GeneratorKind kind) {
  switch (kind) {
    case GeneratorKind::Explode: return "explode";
    case GeneratorKind::Wave: return "wave";
    case GeneratorKind::Swap: return "swap";
  }
  return "?";
}

}  // namespace anim
