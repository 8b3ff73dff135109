// BART AFF scenes -> anim::Animation: expands the parsed scene graph (includes instanced), then
// samples every frame by evaluating each animated transform once and moving whole objects with it.
// Geometry under static transforms only is transformed once and copied into every keyframe.
#include "anim/bart.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <mutex>
#include <thread>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "bart_scene.hpp"

namespace anim {

namespace {

using namespace bart_detail;

constexpr uint64_t kMaxFrames = 1'000'000;
// Frames per time unit when a scene has animation but no `a` line and the caller gave no rate.
constexpr double kFallbackFps = 25.0;

Affine multiply(const Affine& a, const Affine& b) {
  Affine r;
  for (int row = 0; row < 3; ++row) {
    const double* ar = &a[4 * row];
    for (int col = 0; col < 4; ++col)
      r[4 * row + col] = ar[0] * b[col] + ar[1] * b[4 + col] + ar[2] * b[8 + col] + (col == 3 ? ar[3] : 0.0);
  }
  return r;
}

void transformPoints(const Affine& m, const float* src, std::size_t count, float* dst) {
  for (std::size_t i = 0; i < count; ++i, src += 3, dst += 3) {
    const double x = src[0], y = src[1], z = src[2];
    dst[0] = static_cast<float>(m[0] * x + m[1] * y + m[2] * z + m[3]);
    dst[1] = static_cast<float>(m[4] * x + m[5] * y + m[6] * z + m[7]);
    dst[2] = static_cast<float>(m[8] * x + m[9] * y + m[10] * z + m[11]);
  }
}

bool visibleAt(const KeyBlock& kb, double t) {
  bool visible = true;  // visible until the first visibility key
  for (const auto& [time, flag] : kb.visibility) {
    if (t < time) break;
    visible = flag;
  }
  return visible;
}

// T(t) * R(t) * S(t) of a `k` block; an invisible object collapses onto its origin (zero-area
// triangles), so the topology stays constant.
Affine animatedTransform(const KeyBlock& kb, double t) {
  std::array<double, 9> r{1, 0, 0, 0, 1, 0, 0, 0, 1};
  if (kb.rotation) r = bart::rotationMatrix(kb.rotation->at(t));
  const std::array<double, 3> s = kb.scale ? kb.scale->at(t) : std::array<double, 3>{1, 1, 1};
  const std::array<double, 3> p = kb.translation ? kb.translation->at(t) : std::array<double, 3>{0, 0, 0};
  const bool visible = visibleAt(kb, t);
  Affine m;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) m[4 * row + col] = visible ? r[3 * row + col] * s[col] : 0.0;
    m[4 * row + 3] = p[row];
  }
  return m;
}

// The scene with every include expanded: a flat list of transform nodes (parents first) and the
// geometry attached to them, each with its range in the output vertex array.
struct FlatScene {
  struct Node {
    int32_t parent = -1;
    const Affine* local = nullptr;  // static transform, or
    int32_t animation = -1;         // index into `animations`
    bool dynamic = false;           // this node or an ancestor is animated
  };
  struct Instance {
    uint32_t node;
    const Geometry* geometry;
    uint32_t firstVertex;
  };
  struct TriangleInstance {
    uint32_t node;
    const AnimatedTriangle* triangle;
    uint32_t firstVertex;
  };
  std::vector<Node> nodes;
  std::vector<Instance> instances;
  std::vector<TriangleInstance> triangles;
  std::vector<const KeyBlock*> animations;
  std::vector<uint32_t> indices;
  uint32_t vertexCount = 0;
};

class Flattener {
 public:
  Flattener(const ParsedScene& scene, std::vector<std::string>& warnings) : scene_(scene), warnings_(warnings) {}

  FlatScene run() {
    out_.nodes.push_back({});  // the root: identity
    walk(scene_.root->root, 0);
    return std::move(out_);
  }

 private:
  void walk(const Block& b, uint32_t parent) {
    uint32_t node = parent;
    if (b.kind != Block::Kind::Group) {
      FlatScene::Node n;
      n.parent = static_cast<int32_t>(parent);
      n.dynamic = out_.nodes[parent].dynamic;
      if (b.kind == Block::Kind::Static) {
        n.local = &b.matrix;
      } else {
        n.animation = animationIndex(b);
        if (n.animation >= 0) {
          n.dynamic = true;
        } else {
          n.local = &kIdentity;
        }
      }
      node = static_cast<uint32_t>(out_.nodes.size());
      out_.nodes.push_back(n);
    }
    if (!b.geometry.indices.empty()) {
      out_.instances.push_back({node, &b.geometry, out_.vertexCount});
      for (uint32_t i : b.geometry.indices) out_.indices.push_back(out_.vertexCount + i);
      out_.vertexCount += b.geometry.vertexCount();
    }
    for (const AnimatedTriangle& t : b.animated) {
      out_.triangles.push_back({node, &t, out_.vertexCount});
      for (uint32_t c = 0; c < 3; ++c) out_.indices.push_back(out_.vertexCount + c);
      out_.vertexCount += 3;
    }
    for (const Block::Child& c : b.children) walk(c.block ? *c.block : c.include->root, node);
  }

  int32_t animationIndex(const Block& b) {
    const auto known = index_.find(b.name);
    if (known != index_.end()) return known->second;
    int32_t id = -1;
    const auto it = scene_.keys.find(b.name);
    if (it != scene_.keys.end()) {
      id = static_cast<int32_t>(out_.animations.size());
      out_.animations.push_back(&it->second);
    } else {
      warnings_.push_back(b.file + ": line " + std::to_string(b.line) + ": transform '" + b.name +
                          "' has no 'k' block; left unanimated");
    }
    index_[b.name] = id;
    return id;
  }

  const ParsedScene& scene_;
  std::vector<std::string>& warnings_;
  FlatScene out_;
  std::map<std::string, int32_t> index_;
};

std::vector<double> frameTimes(const ParsedScene& scene, const FlatScene& flat, const BartOptions& options,
                               const std::string& path, std::vector<std::string>& warnings) {
  const double fps = options.fps;
  if (!(fps >= 0.0) || !std::isfinite(fps)) throw tsah::FileError(path, "frame rate must be a finite number >= 0");
  double t0 = 0.0, t1 = 0.0;
  uint64_t frames = 1;
  if (scene.range) {
    t0 = scene.range->t0;
    t1 = scene.range->t1;
    frames = static_cast<uint64_t>(scene.range->frames);
  } else {
    // No `a` line: cover the time span of whatever moves.
    bool any = false;
    auto cover = [&](double a, double b) {
      t0 = any ? std::min(t0, a) : a;
      t1 = any ? std::max(t1, b) : b;
      any = true;
    };
    for (const KeyBlock* kb : flat.animations) {
      if (kb->translation) cover(kb->translation->startTime(), kb->translation->endTime());
      if (kb->rotation) cover(kb->rotation->startTime(), kb->rotation->endTime());
      if (kb->scale) cover(kb->scale->startTime(), kb->scale->endTime());
    }
    for (const auto& t : flat.triangles) cover(t.triangle->times.front(), t.triangle->times.back());
    if (t1 > t0 && fps == 0.0) {
      const double count = std::floor((t1 - t0) * kFallbackFps + 1e-9) + 1.0;
      if (count > double(kMaxFrames)) throw tsah::FileError(path, "the animation is too long to sample");
      frames = static_cast<uint64_t>(count);
      warnings.push_back(path + ": no 'a' line; sampling the animated time span [" + std::to_string(t0) + ", " +
                         std::to_string(t1) + "] at " + std::to_string(int(kFallbackFps)) + " frames per time unit");
    }
  }
  if (fps > 0.0 && t1 > t0) {
    const double count = std::floor((t1 - t0) * fps + 1e-9) + 1.0;
    if (!(count <= double(kMaxFrames)))
      throw tsah::FileError(path, "sampling [" + std::to_string(t0) + ", " + std::to_string(t1) + "] at " +
                                  std::to_string(fps) + " fps gives more than " + std::to_string(kMaxFrames) + " frames");
    std::vector<double> times(static_cast<std::size_t>(count));
    for (std::size_t i = 0; i < times.size(); ++i) times[i] = t0 + double(i) / fps;
    return times;
  }
  if (frames > kMaxFrames)
    throw tsah::FileError(scene.range->file, "line " + std::to_string(scene.range->line) + ": frame count " +
                                             std::to_string(frames) + " exceeds the limit of " + std::to_string(kMaxFrames));
  if (frames <= 1 || !(t1 > t0)) return {t0};
  std::vector<double> times(frames);
  for (uint64_t i = 0; i < frames; ++i) times[i] = t0 + (t1 - t0) * double(i) / double(frames - 1);
  times.back() = t1;
  // Times so close that they round together would break the strictly increasing keyframe times.
  for (std::size_t i = 1; i < times.size(); ++i)
    if (!(times[i] > times[i - 1]))
      throw tsah::FileError(scene.range->file, "line " + std::to_string(scene.range->line) +
                                               ": the frame times are too close together to tell apart");
  return times;
}

std::array<float, 3> toFloat(const std::array<double, 3>& v) {
  return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
}

// The `v` view, moved by the `k camera` block when there is one (the BART convention: the camera
// looks down its local -z axis with +y up, placed at the block's translation).
std::vector<CameraKey> cameraPath(const ParsedScene& scene, const std::vector<double>& times) {
  const auto cam = scene.keys.find("camera");
  const bool animated = cam != scene.keys.end() && (cam->second.translation || cam->second.rotation);
  if (!scene.view && !animated) return {};
  const View view = scene.view.value_or(View{});
  const std::array<double, 3> viewDir{view.at[0] - view.from[0], view.at[1] - view.from[1], view.at[2] - view.from[2]};
  const double dist = std::sqrt(viewDir[0] * viewDir[0] + viewDir[1] * viewDir[1] + viewDir[2] * viewDir[2]);
  std::vector<CameraKey> keys;
  for (double t : animated ? times : std::vector<double>{times.front()}) {
    CameraKey k;
    k.time = t;
    k.fovyDegrees = static_cast<float>(view.angle);
    std::array<double, 3> eye = view.from, dir = viewDir, up = view.up;
    if (animated) {
      const KeyBlock& kb = cam->second;
      if (kb.translation) eye = kb.translation->at(t);
      if (kb.rotation) {
        const auto r = bart::rotationMatrix(kb.rotation->at(t));
        const double d = dist > 0.0 ? dist : 1.0;
        dir = {-r[2] * d, -r[5] * d, -r[8] * d};
        up = {r[1], r[4], r[7]};
      }
    }
    k.eye = toFloat(eye);
    k.lookAt = toFloat({eye[0] + dir[0], eye[1] + dir[1], eye[2] + dir[2]});
    k.up = toFloat(up);
    keys.push_back(k);
  }
  return keys;
}

std::string byteSize(long double bytes) {
  const char* units[] = {"bytes", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (bytes >= 1024 && u < 4) {
    bytes /= 1024;
    ++u;
  }
  char text[64];
  std::snprintf(text, sizeof text, u == 0 ? "%.0Lf %s" : "%.1Lf %s", bytes, units[u]);
  return text;
}

std::string skippedSummary(const ParsedScene& s) {
  std::vector<std::string> parts;
  auto add = [&](uint64_t n, const char* one, const char* many) {
    if (n) parts.push_back(std::to_string(n) + " " + (n == 1 ? one : many));
  };
  add(s.materials, "material", "materials");
  add(s.lights, "light", "lights");
  add(s.textures, "texture reference", "texture references");
  add(s.backgrounds, "background colour", "background colours");
  if (parts.empty()) return {};
  std::string out = "skipped ";
  for (std::size_t i = 0; i < parts.size(); ++i)
    out += (i == 0 ? "" : i + 1 == parts.size() ? " and " : ", ") + parts[i];
  return out + " (only geometry and the camera are imported)";
}

Animation sample(const ParsedScene& scene, const std::string& path, const BartOptions& options) {
  std::vector<std::string> warnings = scene.warnings;
  const FlatScene flat = Flattener(scene, warnings).run();
  if (flat.indices.empty()) throw tsah::FileError(path, "the scene holds no triangles");
  const std::vector<double> times = frameTimes(scene, flat, options, path, warnings);

  const std::size_t perFrame = std::size_t(flat.vertexCount) * 3;
  const long double bytes = (long double)perFrame * sizeof(float) * (long double)times.size();
  if (bytes > (long double)options.maxPositionBytes)
    throw tsah::FileError(path, std::to_string(times.size()) + " frames x " + std::to_string(flat.vertexCount) +
                                " vertices need " + byteSize(bytes) + " of keyframe positions, more than the limit of " +
                                byteSize((long double)options.maxPositionBytes) + "; sample fewer frames");

  // World transforms and positions of everything that never moves, computed once.
  const std::size_t nodeCount = flat.nodes.size();
  std::vector<Affine> staticWorld(nodeCount, kIdentity);
  for (std::size_t i = 1; i < nodeCount; ++i) {
    const auto& n = flat.nodes[i];
    if (!n.dynamic) staticWorld[i] = multiply(staticWorld[n.parent], *n.local);
  }
  std::vector<float> base(perFrame, 0.0f);
  for (const auto& inst : flat.instances)
    if (!flat.nodes[inst.node].dynamic)
      transformPoints(staticWorld[inst.node], inst.geometry->positions.data(), inst.geometry->vertexCount(),
                      base.data() + 3 * std::size_t(inst.firstVertex));

  std::vector<float> positions(perFrame * times.size());
  std::mutex progressMutex;
  std::atomic<std::size_t> done{0};
  auto sampleFrames = [&](std::size_t begin, std::size_t end) {
    std::vector<Affine> world = staticWorld;
    std::vector<Affine> animLocal(flat.animations.size());
    for (std::size_t f = begin; f < end; ++f) {
      const double t = times[f];
      float* out = positions.data() + f * perFrame;
      std::memcpy(out, base.data(), perFrame * sizeof(float));
      for (std::size_t a = 0; a < flat.animations.size(); ++a) animLocal[a] = animatedTransform(*flat.animations[a], t);
      for (std::size_t i = 1; i < nodeCount; ++i) {
        const auto& n = flat.nodes[i];
        if (!n.dynamic) continue;
        world[i] = multiply(world[n.parent], n.animation >= 0 ? animLocal[n.animation] : *n.local);
      }
      for (const auto& inst : flat.instances)
        if (flat.nodes[inst.node].dynamic)
          transformPoints(world[inst.node], inst.geometry->positions.data(), inst.geometry->vertexCount(),
                          out + 3 * std::size_t(inst.firstVertex));
      for (const auto& tri : flat.triangles) {
        // Linear blend of the two key shapes around t, clamped at the ends.
        const auto& keyTimes = tri.triangle->times;
        const float* corners = tri.triangle->corners.data();
        float shape[9];
        const std::size_t k = std::size_t(std::upper_bound(keyTimes.begin(), keyTimes.end(), t) - keyTimes.begin());
        if (k == 0 || k == keyTimes.size()) {
          std::memcpy(shape, corners + 9 * (k == 0 ? 0 : keyTimes.size() - 1), sizeof shape);
        } else {
          const double span = keyTimes[k] - keyTimes[k - 1];
          const double w = span > 0.0 ? (t - keyTimes[k - 1]) / span : 1.0;
          for (int c = 0; c < 9; ++c)
            shape[c] = static_cast<float>((1.0 - w) * corners[9 * (k - 1) + c] + w * corners[9 * k + c]);
        }
        transformPoints(world[tri.node], shape, 3, out + 3 * std::size_t(tri.firstVertex));
      }
      const std::size_t finished = ++done;
      if (options.progress) {
        std::lock_guard<std::mutex> lock(progressMutex);
        options.progress(finished, times.size());
      }
    }
  };
  const std::size_t threads = std::max<std::size_t>(
      1, std::min<std::size_t>({std::thread::hardware_concurrency(), 16, times.size() / 8 + 1}));
  if (threads == 1) {
    sampleFrames(0, times.size());
  } else {
    std::vector<std::thread> pool;
    std::vector<std::exception_ptr> errors(threads);
    for (std::size_t k = 0; k < threads; ++k)
      pool.emplace_back([&, k] {
        try {
          sampleFrames(times.size() * k / threads, times.size() * (k + 1) / threads);
        } catch (...) {
          errors[k] = std::current_exception();
        }
      });
    for (auto& th : pool) th.join();
    for (auto& e : errors)
      if (e) std::rethrow_exception(e);
  }

  if (const std::string summary = skippedSummary(scene); !summary.empty()) warnings.push_back(path + ": " + summary);
  if (options.warning)
    for (const auto& w : warnings) options.warning(w);

  std::string name = std::filesystem::path(path).stem().string();
  Animation result(flat.indices, flat.vertexCount, std::move(positions), times, name);
  result.setCameraPath(cameraPath(scene, times));
  return result;
}

}  // namespace

Animation importBartText(std::string_view text, const std::string& path, const BartOptions& options) {
  const ParsedScene scene = parseScene(text, path, options);
  return sample(scene, path, options);
}

Animation importBart(const std::string& path, const BartOptions& options) {
  const std::vector<uint8_t> bytes = tsah::readFile(path, std::size_t(1) << 30);
  return importBartText(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), path, options);
}

}  // namespace anim
