// Reads `tsah export TREE SCENE` of a two-level scene as a renderer would, from the format its
// header (tsah_scene.h) describes, and checks it against tsah::TwoLevelRuntime at the same time:
// the sizes are the header's counts, every offset and reference is in range, each slot's Woop rows
// are those of its triangle's exported vertices, the instance table is the runtime's (world(t),
// its inverse, visibility, view), and a batch of rays traced through the exported
// TLAS, instance transforms and BLAS views gives the runtime's closest hits (instance, triangle, t).
//
// Usage: check_two_level_export SCENE TREE DIR TIME [FILE=OTHER_DIR ...]
// FILE=OTHER_DIR reads FILE from another export instead (the tests feed it a file of another time,
// which must make the check fail). Prints "two-level export: ... ok" and exits 0, or names the
// first problem and exits 1.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "tsah/layout/woop.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace {

// The records of the header (TsahBlas, TsahBlasView, TsahInstance, TsahBvhNode), as documented.
struct Blas {
  uint32_t triangleCount, vertexCount, triangleOffset, animated;
};
struct View {
  uint32_t blas, pose, nodeOffset, nodeCount, woopOffset, woopCount, vertexOffset, depth;
  int32_t rootRef;
  uint32_t rootCount;
  float localTime;
  uint32_t reserved;
  float lo[3], hi[3];
};
struct Instance {
  float toWorld[12], toInstance[12], lo[3], hi[3];
  uint32_t view, blas, visible, reserved;
};
struct BinaryNode {
  float c0lx, c0hx, c0ly, c0hy, c1lx, c1hx, c1ly, c1hy, c0lz, c0hz, c1lz, c1hz;
  int32_t ref[2];
  uint32_t count[2];
};
static_assert(sizeof(Blas) == 16 && sizeof(View) == 72 && sizeof(Instance) == 136 && sizeof(BinaryNode) == 64);

struct Fail {
  std::string what;
};
void require(bool ok, const std::string& what) {
  if (!ok) throw Fail{what};
}

struct Files {
  std::string dir;
  std::map<std::string, std::string> from;  // FILE -> OTHER_DIR
  std::vector<char> read(const std::string& name) const {
    const auto other = from.find(name);
    const std::string path = (other == from.end() ? dir : other->second) + "/" + name;
    std::ifstream in(path, std::ios::binary);
    require(bool(in), "cannot read " + path);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  template <typename T>
  std::vector<T> array(const std::string& name, uint64_t count) const {
    const std::vector<char> bytes = read(name);
    require(bytes.size() == count * sizeof(T), name + ": " + std::to_string(bytes.size()) + " bytes, the header gives " +
                                                   std::to_string(count) + " x " + std::to_string(sizeof(T)));
    std::vector<T> out(count);
    if (!bytes.empty()) std::memcpy(out.data(), bytes.data(), bytes.size());
    return out;
  }
};

struct Hit {
  float t = INFINITY;
  uint32_t instance = tsah::kNoHit, prim = tsah::kNoHit;
};

// Slab test of a box against the ray over [tmin, tmax].
bool hitsBox(const float lo[3], const float hi[3], const float o[3], const float inv[3], float tmin, float tmax) {
  for (int a = 0; a < 3; ++a) {
    float t0 = (lo[a] - o[a]) * inv[a], t1 = (hi[a] - o[a]) * inv[a];
    if (t0 > t1) std::swap(t0, t1);
    tmin = std::max(tmin, t0);
    tmax = std::min(tmax, t1);
  }
  return tmin <= tmax;
}

// The header's Woop test on rows r[12] (r0.xyzw, r1.xyzw, r2.xyzw).
bool woopTest(const float r[12], const float o[3], const float d[3], float tmin, float tmax, float& t) {
  t = (r[3] - (o[0] * r[0] + o[1] * r[1] + o[2] * r[2])) / (d[0] * r[0] + d[1] * r[1] + d[2] * r[2]);
  if (!(t > tmin && t < tmax)) return false;
  const float b0 = r[7] + (o[0] * r[4] + o[1] * r[5] + o[2] * r[6]) + t * (d[0] * r[4] + d[1] * r[5] + d[2] * r[6]);
  const float b1 = r[11] + (o[0] * r[8] + o[1] * r[9] + o[2] * r[10]) + t * (d[0] * r[8] + d[1] * r[9] + d[2] * r[10]);
  return b0 >= 0.0f && b1 >= 0.0f && b0 + b1 <= 1.0f;
}

struct Export {
  uint32_t width = 2;
  std::vector<Blas> blases;
  std::vector<View> views;
  std::vector<char> nodes, woop;  // the layout's node and Woop records
  std::vector<float> vertices;
  std::vector<uint32_t> triIndex, indices, tlasIndex;
  std::vector<BinaryNode> tlas;
  std::vector<Instance> instances;
  int32_t tlasRoot = 0;
  uint32_t tlasRootCount = 0;

  std::size_t nodeBytes() const { return width == 2 ? 64 : width == 4 ? 128 : 256; }
  std::size_t woopBytes() const { return width == 2 ? 48 : width == 4 ? 208 : 416; }
  const float* node(const View& v, int32_t ref) const {
    return reinterpret_cast<const float*>(nodes.data() + (v.nodeOffset + std::size_t(ref)) * nodeBytes());
  }
  // Rows of the triangle in binary slot s / wide packet p lane l (12 floats, gathered).
  void rows(const View& v, uint32_t record, uint32_t lane, float r[12]) const {
    const float* w = reinterpret_cast<const float*>(woop.data() + (v.woopOffset + std::size_t(record)) * woopBytes());
    for (int k = 0; k < 12; ++k) r[k] = width == 2 ? w[k] : w[k * width + lane];
  }
  uint32_t laneSlot(const View& v, uint32_t packet, uint32_t lane) const {
    const char* p = woop.data() + (v.woopOffset + std::size_t(packet)) * woopBytes() + 48 * width;
    uint32_t s;
    std::memcpy(&s, p + 4 * lane, 4);
    return s;
  }

  void traceBlas(const View& v, const float o[3], const float d[3], float tmin, uint32_t instance, Hit& best) const {
    const float inv[3] = {1.0f / d[0], 1.0f / d[1], 1.0f / d[2]};
    const Blas& b = blases[v.blas];
    std::vector<std::pair<int32_t, uint32_t>> stack{{v.rootRef, v.rootCount}};
    while (!stack.empty()) {
      const auto [ref, count] = stack.back();
      stack.pop_back();
      if (ref >= 0) {
        require(uint32_t(ref) < v.nodeCount, "a BLAS node reference is out of its view's range");
        const float* n = node(v, ref);
        if (width == 2) {
          const BinaryNode& bn = *reinterpret_cast<const BinaryNode*>(n);
          const float lo0[3] = {bn.c0lx, bn.c0ly, bn.c0lz}, hi0[3] = {bn.c0hx, bn.c0hy, bn.c0hz};
          const float lo1[3] = {bn.c1lx, bn.c1ly, bn.c1lz}, hi1[3] = {bn.c1hx, bn.c1hy, bn.c1hz};
          if (hitsBox(lo0, hi0, o, inv, tmin, best.t)) stack.push_back({bn.ref[0], bn.count[0]});
          if (hitsBox(lo1, hi1, o, inv, tmin, best.t)) stack.push_back({bn.ref[1], bn.count[1]});
        } else {
          const int32_t* refs = reinterpret_cast<const int32_t*>(n + 6 * width);
          const uint32_t* counts = reinterpret_cast<const uint32_t*>(n + 7 * width);
          for (uint32_t c = 0; c < width; ++c) {
            if (refs[c] == 0 && counts[c] == 0) continue;  // unused child slot
            const float lo[3] = {n[c], n[width + c], n[2 * width + c]};
            const float hi[3] = {n[3 * width + c], n[4 * width + c], n[5 * width + c]};
            if (hitsBox(lo, hi, o, inv, tmin, best.t)) stack.push_back({refs[c], counts[c]});
          }
        }
        continue;
      }
      for (uint32_t k = 0; k < count; ++k) {
        const uint32_t record = width == 2 ? uint32_t(~ref) + k : uint32_t(~ref) + k / width;
        const uint32_t lane = width == 2 ? 0 : k % width;
        require(record < v.woopCount, "a BLAS leaf reference is out of its view's range");
        const uint32_t slot = width == 2 ? record : laneSlot(v, record, lane);
        require(slot < b.triangleCount, "a slot is out of its BLAS's range");
        float r[12], t;
        rows(v, record, lane, r);
        if (woopTest(r, o, d, tmin, best.t, t)) best = {t, instance, triIndex[b.triangleOffset + slot]};
      }
    }
  }

  Hit trace(const tsah::Ray& ray) const {
    const float o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
    const float inv[3] = {1.0f / d[0], 1.0f / d[1], 1.0f / d[2]};
    Hit best;
    best.t = ray.tmax;
    std::vector<std::pair<int32_t, uint32_t>> stack{{tlasRoot, tlasRootCount}};
    while (!stack.empty()) {
      const auto [ref, count] = stack.back();
      stack.pop_back();
      if (ref >= 0) {
        const BinaryNode& n = tlas.at(std::size_t(ref));
        const float lo0[3] = {n.c0lx, n.c0ly, n.c0lz}, hi0[3] = {n.c0hx, n.c0hy, n.c0hz};
        const float lo1[3] = {n.c1lx, n.c1ly, n.c1lz}, hi1[3] = {n.c1hx, n.c1hy, n.c1hz};
        if (hitsBox(lo0, hi0, o, inv, ray.tmin, best.t)) stack.push_back({n.ref[0], n.count[0]});
        if (hitsBox(lo1, hi1, o, inv, ray.tmin, best.t)) stack.push_back({n.ref[1], n.count[1]});
        continue;
      }
      for (uint32_t s = uint32_t(~ref); s < uint32_t(~ref) + count; ++s) {
        const uint32_t i = tlasIndex.at(s);
        const Instance& in = instances.at(i);
        if (!in.visible) continue;
        const float* m = in.toInstance;  // origin by the map, direction by its linear part
        const float lo[3] = {m[0] * o[0] + m[1] * o[1] + m[2] * o[2] + m[3], m[4] * o[0] + m[5] * o[1] + m[6] * o[2] + m[7],
                             m[8] * o[0] + m[9] * o[1] + m[10] * o[2] + m[11]};
        const float ld[3] = {m[0] * d[0] + m[1] * d[1] + m[2] * d[2], m[4] * d[0] + m[5] * d[1] + m[6] * d[2],
                             m[8] * d[0] + m[9] * d[1] + m[10] * d[2]};
        traceBlas(views.at(in.view), lo, ld, ray.tmin, i, best);
      }
    }
    if (best.instance == tsah::kNoHit) best.t = INFINITY;
    return best;
  }
};

uint64_t define(const std::string& header, const std::string& name) {
  std::smatch m;
  require(std::regex_search(header, m, std::regex("#define " + name + " \\(?(-?[0-9]+)")), "the header lacks " + name);
  return uint64_t(std::stoll(m[1]));
}

Export readExport(const Files& files) {
  const std::vector<char> text = files.read("tsah_scene.h");
  const std::string h(text.begin(), text.end());
  require(define(h, "TSAH_TWO_LEVEL") == 1, "the header is not a two-level export's");
  Export e;
  e.width = uint32_t(define(h, "TSAH_BLAS_WIDTH"));
  require(e.width == 2 || e.width == 4 || e.width == 8, "TSAH_BLAS_WIDTH is not 2, 4 or 8");
  e.blases = files.array<Blas>("blases.bin", define(h, "TSAH_BLAS_COUNT"));
  e.views = files.array<View>("views.bin", define(h, "TSAH_VIEW_COUNT"));
  e.instances = files.array<Instance>("instances.bin", define(h, "TSAH_INSTANCE_COUNT"));
  e.nodes = files.array<char>("blas_nodes.bin", define(h, "TSAH_BLAS_NODE_COUNT") * e.nodeBytes());
  e.woop = files.array<char>("blas_woop.bin", define(h, "TSAH_BLAS_WOOP_COUNT") * e.woopBytes());
  e.vertices = files.array<float>("blas_vertices.bin", 3 * define(h, "TSAH_BLAS_VERTEX_COUNT"));
  e.triIndex = files.array<uint32_t>("blas_tri_index.bin", define(h, "TSAH_BLAS_TRIANGLE_COUNT"));
  e.indices = files.array<uint32_t>("blas_indices.bin", 3 * define(h, "TSAH_BLAS_TRIANGLE_COUNT"));
  e.tlas = files.array<BinaryNode>("tlas_nodes.bin", define(h, "TSAH_TLAS_NODE_COUNT"));
  e.tlasIndex = files.array<uint32_t>("tlas_index.bin", e.instances.size());
  e.tlasRoot = int32_t(int64_t(define(h, "TSAH_TLAS_ROOT_REF")));
  e.tlasRootCount = uint32_t(define(h, "TSAH_TLAS_ROOT_COUNT"));
  // Offsets: views follow each other, BLAS triangle ranges too; every reference in range.
  uint64_t node = 0, woop = 0, slot = 0;
  for (const Blas& b : e.blases) {
    require(b.triangleOffset == slot, "blases.bin: triangle offsets do not follow each other");
    slot += b.triangleCount;
  }
  require(slot == e.triIndex.size(), "blases.bin: the triangle counts do not add up to TSAH_BLAS_TRIANGLE_COUNT");
  uint64_t vertex = 0;
  for (const View& v : e.views) {
    require(v.blas < e.blases.size() && v.nodeOffset == node && v.woopOffset == woop && v.vertexOffset == vertex,
            "views.bin: a view's BLAS or offsets are wrong");
    node += v.nodeCount, woop += v.woopCount, vertex += e.blases[v.blas].vertexCount;
  }
  require(node * e.nodeBytes() == e.nodes.size() && woop * e.woopBytes() == e.woop.size() && 3 * vertex == e.vertices.size(),
          "views.bin: the views do not cover the node, Woop and vertex files");
  for (const Instance& in : e.instances)
    require(in.view < e.views.size() && e.views[in.view].blas == in.blas, "instances.bin: a view or BLAS is wrong");
  return e;
}

// Every slot's Woop rows are those of its triangle's exported vertices (the runtime's rounding).
void checkTriangles(const Export& e) {
  for (const View& v : e.views) {
    const Blas& b = e.blases[v.blas];
    for (uint32_t record = 0; record < v.woopCount; ++record)
      for (uint32_t lane = 0; lane < (e.width == 2 ? 1u : e.width); ++lane) {
        float r[12];
        e.rows(v, record, lane, r);
        const uint32_t slot = e.width == 2 ? record : e.laneSlot(v, record, lane);
        if (e.width != 2 && std::all_of(r, r + 12, [](float x) { return x == 0.0f; })) continue;  // padding
        require(slot < b.triangleCount, "a Woop packet's slot is out of range");
        const uint32_t id = e.triIndex[b.triangleOffset + slot];
        require(id < b.triangleCount, "blas_tri_index.bin: a triangle id is out of range");
        tsah::Vec3 p[3];
        for (int k = 0; k < 3; ++k) {
          const uint32_t vi = e.indices[3 * (std::size_t(b.triangleOffset) + id) + k];
          require(vi < b.vertexCount, "blas_indices.bin: a vertex id is out of range");
          const float* q = &e.vertices[3 * (std::size_t(v.vertexOffset) + vi)];
          p[k] = {q[0], q[1], q[2]};
        }
        const tsah::WoopTriangle w = tsah::makeWoopTriangle(p[0], p[1], p[2]);
        const float expect[12] = {w.r0.x, w.r0.y, w.r0.z, w.r0.w, w.r1.x, w.r1.y,
                                  w.r1.z, w.r1.w, w.r2.x, w.r2.y, w.r2.z, w.r2.w};
        require(std::memcmp(expect, r, sizeof r) == 0, "blas_woop.bin: the rows of a slot are not its triangle's vertices'");
      }
  }
}

// Each instance's world(t), inverse and visibility are those the runtimes compute (instanceSpace),
// its view the static BLAS's or its pose's.
void checkInstances(const Export& e, const tsah::TwoLevelScene& scene, double time) {
  require(e.instances.size() == scene.instanceCount() && e.blases.size() == scene.blases.size(),
          "the instance or BLAS count is not the scene's");
  uint32_t staticViews = 0;
  for (const tsah::Blas& b : scene.blases) staticViews += b.animated ? 0 : 1;
  for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
    const Instance& in = e.instances[i];
    const anim::Matrix4 world = scene.scene.instances[i].worldAt(time);
    const std::optional<tsah::Affine3x4> space = tsah::instanceSpace(world);
    float toWorld[12], toInstance[12];
    for (int k = 0; k < 12; ++k) {
      toWorld[k] = float(world[k]);
      toInstance[k] = space ? space->m[k] : 0.0f;
    }
    const std::string which = "instances.bin: instance " + std::to_string(i) + ": ";
    require(std::memcmp(toWorld, in.toWorld, sizeof toWorld) == 0, which + "toWorld is not world(t)");
    require(std::memcmp(toInstance, in.toInstance, sizeof toInstance) == 0, which + "toInstance is not its inverse");
    require(in.visible == (space ? 1u : 0u), which + "the visibility is wrong");
    const uint32_t pose = scene.instancePose[i];
    const View& v = e.views[in.view];
    require(v.blas == scene.scene.instances[i].source && v.pose == pose &&
                (pose == tsah::kInvalidIndex ? in.view < staticViews : in.view == staticViews + pose),
            which + "the view is not its BLAS's or pose's");
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: check_two_level_export SCENE TREE DIR TIME [FILE=OTHER_DIR ...]\n");
    return 2;
  }
  try {
    Files files{argv[3], {}};
    for (int a = 5; a < argc; ++a) {
      const std::string arg = argv[a];
      files.from[arg.substr(0, arg.find('='))] = arg.substr(arg.find('=') + 1);
    }
    const double time = std::stod(argv[4]);
    const Export e = readExport(files);
    checkTriangles(e);

    const tsah::TwoLevelScene scene = tsah::loadTwoLevelSceneFile(argv[2], anim::loadSceneSources(argv[1], {}));
    tsah::TwoLevelRuntime reference(scene);
    reference.update(time);
    // Rays from random points around the scene to the centroid of a random triangle of a random
    // instance (never aimed at an edge), and as many in random directions.
    const tsah::Aabb bounds = reference.tlas().rootBoxes[0];
    const tsah::Vec3 size = bounds.hi - bounds.lo;
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const auto around = [&] {
      return tsah::Vec3{bounds.lo.x - size.x + 3.0f * size.x * unit(rng), bounds.lo.y - size.y + 3.0f * size.y * unit(rng),
                        bounds.lo.z - size.z + 3.0f * size.z * unit(rng)};
    };
    uint32_t rays = 0, hits = 0, mismatches = 0;
    for (int n = 0; n < 4000; ++n) {
      const uint32_t i = uint32_t(rng() % scene.instanceCount());
      const tsah::CpuRuntime& blas = reference.blasOf(i);
      const uint32_t tri = uint32_t(rng() % blas.triangleCount());
      tsah::Vec3 c{0, 0, 0};
      for (int k = 0; k < 3; ++k) {
        const float* q = &blas.positions()[3 * std::size_t(blas.indices()[3 * tri + k])];
        c = c + tsah::Vec3{q[0], q[1], q[2]} * (1.0f / 3.0f);
      }
      const anim::Matrix4 w = scene.scene.instances[i].worldAt(time);
      const tsah::Vec3 target{float(w[0] * c.x + w[1] * c.y + w[2] * c.z + w[3]),
                              float(w[4] * c.x + w[5] * c.y + w[6] * c.z + w[7]),
                              float(w[8] * c.x + w[9] * c.y + w[10] * c.z + w[11])};
      const tsah::Vec3 org = around();
      const tsah::Vec3 dir = n % 2 == 0 ? target - org : around() - org;
      const tsah::Ray ray{org, 0.0f, dir, INFINITY};
      const tsah::TwoLevelHit want = reference.closestHit(ray);
      const Hit got = e.trace(ray);
      ++rays;
      hits += want.valid() ? 1 : 0;
      const bool same = want.valid() ? got.instance == want.instance && got.prim == want.prim &&
                                           std::fabs(got.t - want.t) <= 1e-4f * std::max(1.0f, want.t)
                                     : got.instance == tsah::kNoHit;
      if (!same && ++mismatches <= 3)
        std::printf("ray %d: runtime instance %u triangle %u t %g, export instance %u triangle %u t %g\n", n,
                    want.instance, want.prim, double(want.t), got.instance, got.prim, double(got.t));
    }
    // Ties between coincident surfaces and the edge band of the runtime's watertight test may name
    // another triangle: at most 1 ray in 200 (none on the test scene).
    require(hits >= rays / 8, "too few rays hit the scene (" + std::to_string(hits) + " of " + std::to_string(rays) + ")");
    require(mismatches * 200 <= rays, std::to_string(mismatches) + " of " + std::to_string(rays) +
                                          " rays hit otherwise than the runtime");
    checkInstances(e, scene, time);  // after the rays: a wrong table must show in the hits first
    // The TLAS of the time's part (a structure of several TLAS trees): the runtime's at that time.
    require(e.tlasIndex == reference.tlas().triIndex && e.tlas.size() == reference.tlas().nodes.size(),
            "the TLAS is not the runtime's at time " + std::string(argv[4]));
    std::printf("two-level export (%u-wide BLAS, %zu views, %zu instances): %u rays, %u hits, %u differ: ok\n", e.width,
                e.views.size(), e.instances.size(), rays, hits, mismatches);
    return 0;
  } catch (const Fail& f) {
    std::printf("two-level export: %s\n", f.what.c_str());
  } catch (const std::exception& x) {
    std::printf("two-level export: error: %s\n", x.what());
  }
  return 1;
}
