// Baking a scene: load each object once, state the memory, bake keyframes with static vertices
// stored once.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <map>
#include <memory>
#include <tuple>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/base/parallel_each.hpp"
#include "anim/load.hpp"
#include "anim/scene.hpp"
#include "anim/subdivide.hpp"

namespace anim {

namespace {

// The scene files being baked on this thread, outermost first: a scene that reaches itself again
// through its objects is a cycle.
thread_local std::vector<std::string> sceneStack;

struct SceneStackEntry {
  explicit SceneStackEntry(std::string file) { sceneStack.push_back(std::move(file)); }
  ~SceneStackEntry() { sceneStack.pop_back(); }
  SceneStackEntry(const SceneStackEntry&) = delete;
  SceneStackEntry& operator=(const SceneStackEntry&) = delete;
};

std::string canonical(const std::string& path) {
  std::error_code ec;
  const auto c = std::filesystem::weakly_canonical(path, ec);
  return ec ? path : c.string();
}

std::string mib(uint64_t bytes) { return std::to_string((bytes + (1u << 19)) >> 20) + " MiB"; }

[[noreturn]] void failObject(const SceneDescription& scene, const SceneObject& object, const std::string& what) {
  throw tsah::FileError(scene.file, "object '" + tsah::printable(object.name) + "': " + what);
}

// Vertices of one instance that move: all of them when its path is keyed, none when its source
// never moves (or is frozen by speed 0), else the source's moving vertices.
template <class Instance>  // SceneInstance or SceneSourceInstance
uint64_t movingOf(const Instance& instance, const Animation& source) {
  if (instance.keyed()) return source.vertexCount();
  if (source.keyframeCount() < 2 || instance.time.speed == 0.0) return 0;
  return source.movingVertexCount();
}

// An object that is itself a scene file, counted from the descriptions before any of it is baked
// (only by the outermost scene: it counts every level below): a chain of scenes that doubles at
// every level is refused at once instead of level by level as the bakes grow.
void checkNestedSceneSize(const SceneDescription& scene, const SceneObject& object, const LoadOptions& own) {
  std::string ext = std::filesystem::path(object.file).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext != ".json" || !isSceneFile(object.file)) return;
  const SceneSize one = describedSceneSize(object.file, own);
  __extension__ typedef unsigned __int128 Wide;
  const Wide triangles = Wide(one.triangles) * object.instances.size(), vertices = Wide(one.vertices) * object.instances.size();
  const std::string counted = std::to_string(object.instances.size()) + " instances of a scene of " +
                              std::to_string(one.triangles) + " triangles (counted from its scene files)";
  if (triangles > 0xffffffffu || vertices > 0xffffffffu)
    failObject(scene, object, counted + " would make more than 2^32 triangles or vertices");
  const uint64_t need = Animation::memoryBytesFor(uint64_t(triangles), uint64_t(vertices), 0, 1);
  if (need > tsah::availableMemoryBytes())
    failObject(scene, object, counted + " would need " + mib(need) + ", more than the " +
                                  mib(tsah::availableMemoryBytes()) + " of memory available");
}

// One distinct (file, fps, clip, subdivision) of the scene: loaded once, shared by its objects.
struct SourceJob {
  std::size_t object = 0;  // the first object naming it
  LoadOptions options;
  Animation animation;
  std::exception_ptr error;  // of its load or its subdivision
};

// Refuses a subdivision that is not possible or would not fit: `held` is the memory of everything
// loaded and of the subdivisions that run beside this one.
void checkSubdivision(const SceneDescription& scene, const SceneObject& object, const Animation& a, uint64_t& held) {
  if (a.keyframeCount() != 1)
    failObject(scene, object, "subdivision needs a static mesh (it has " + std::to_string(a.keyframeCount()) +
                                  " keyframes)");
  const MeshCounts after = loopSubdividedCounts(meshCounts(a), object.subdivide);
  if (after.triangles > 0xffffffffull || after.vertices > 0xffffffffull)
    failObject(scene, object, "subdivision level " + std::to_string(object.subdivide) + " would make " +
                                  std::to_string(after.triangles) + " triangles, more than 2^32");
  held += loopSubdivisionBytes(after);
  if (held > tsah::availableMemoryBytes())
    failObject(scene, object, "subdivision level " + std::to_string(object.subdivide) + " (" +
                                  std::to_string(after.triangles) + " triangles) would need " + mib(held) +
                                  ", more than the " + mib(tsah::availableMemoryBytes()) + " available");
}

// Loads (and subdivides) each object's file once; objects naming the same file with the same
// options share it. The distinct files are loaded concurrently, then subdivided concurrently; an
// error is the one the first object in scene order meets, as if they were loaded one by one.
void loadSources(const LoadOptions& options, SceneSources& out) {
  const SceneDescription& scene = out.description;
  std::vector<SourceJob> jobs;
  std::map<std::string, uint32_t> loaded;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const SceneObject& object = scene.objects[o];
    const std::string file = canonical(object.file);
    const double fps = object.fps > 0.0 ? object.fps : options.fps;
    const std::string key = file + "\n" + std::to_string(fps) + "\n" + object.clip + "\n" + std::to_string(object.subdivide);
    const auto [found, added] = loaded.try_emplace(key, uint32_t(jobs.size()));
    out.objectSource.push_back(found->second);
    if (!added) continue;
    SourceJob& job = jobs.emplace_back();
    job.object = o;
    job.options = options;
    job.options.fps = fps;
    job.options.clip = object.clip;
    job.options.progress = nullptr;
    try {
      for (const std::string& outer : sceneStack)
        if (outer == file)
          failObject(scene, object, "scene files include each other (" + object.file + " is being baked already)");
      if (sceneStack.size() == 1) checkNestedSceneSize(scene, object, job.options);
    } catch (...) {
      job.error = std::current_exception();  // met when this object's turn comes
    }
  }

  // A nested scene file loaded on a worker thread sees the scene files being baked here.
  const std::vector<std::string> outerScenes = sceneStack;
  tsah::forEachConcurrently(jobs.size(), [&](std::size_t j) {
    SourceJob& job = jobs[j];
    if (job.error) return;
    std::vector<std::string> own = outerScenes;
    std::swap(own, sceneStack);
    try {
      job.animation = load(scene.objects[job.object].file, job.options);
    } catch (const tsah::Error& e) {
      job.error = std::make_exception_ptr(tsah::FileError(
          scene.file, "object '" + tsah::printable(scene.objects[job.object].name) + "': " + e.what()));
    } catch (...) {
      job.error = std::current_exception();
    }
    std::swap(own, sceneStack);
  });

  // The subdivisions that can run: those before the first load or check that fails.
  uint64_t held = 0;
  for (const SourceJob& job : jobs) held += job.animation.memoryBytes();
  std::size_t runnable = 0;
  std::exception_ptr stop;
  for (; runnable < jobs.size() && !stop; ++runnable) {
    SourceJob& job = jobs[runnable];
    const SceneObject& object = scene.objects[job.object];
    if (job.error) {
      stop = job.error;
    } else if (object.subdivide > 0) {
      try {
        checkSubdivision(scene, object, job.animation, held);
      } catch (...) {
        stop = std::current_exception();
      }
    }
    if (stop) break;
  }
  tsah::forEachConcurrently(runnable, [&](std::size_t j) {
    SourceJob& job = jobs[j];
    const SceneObject& object = scene.objects[job.object];
    if (object.subdivide == 0) return;
    try {
      job.animation = subdivideLoop(job.animation, object.subdivide);
    } catch (const tsah::Error& e) {
      failObject(scene, object, e.what());
    }
  });
  if (stop) std::rethrow_exception(stop);

  for (SourceJob& job : jobs) {
    out.sourceBytes += job.animation.memoryBytes();
    out.sources.push_back(std::make_shared<const Animation>(std::move(job.animation)));
  }
}

// The scene's time range: given, or from 0 to where the last object's motion ends (one pass of a
// looping object, the last key of a path); [0, 0] for a static scene.
std::pair<double, double> timeRange(const SceneSources& loaded) {
  const SceneDescription& scene = loaded.description;
  if (scene.hasTimeRange) return {scene.start, scene.end};
  double end = 0.0;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Animation& a = *loaded.sources[loaded.objectSource[o]];
    for (const SceneInstance& i : scene.objects[o].instances) {
      if (a.keyframeCount() > 1 && i.time.speed > 0.0)
        end = std::max(end, i.time.offset + (a.endTime() - a.startTime()) / i.time.speed);
      if (!i.path.empty()) end = std::max(end, i.path.back().time);
    }
  }
  return {0.0, end};
}

// Keyframes of the bake: start, every 1/fps after it below end, and end (one when end <= start).
// Counted in floating point first, so a long range at a high rate is refused by the memory
// statement instead of being discovered while the times are filled in.
double bakeKeyframeCount(double start, double end, double fps) {
  if (!(end > start)) return 1.0;
  return std::max(std::ceil((end - start) * fps - 1e-9), 1.0) + 1.0;
}

std::vector<double> bakeTimes(double start, double end, double fps) {
  std::vector<double> times{start};
  if (!(end > start)) return times;
  const double frames = bakeKeyframeCount(start, end, fps) - 1.0;
  for (double i = 1; i < frames; ++i) times.push_back(start + i / fps);
  times.push_back(end);
  return times;
}

// The scene's instance ids 0 .. n - 1.
std::vector<uint32_t> allInstances(const SceneSources& loaded) {
  std::vector<uint32_t> all(loaded.instances.size());
  for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  return all;
}

// Triangles, vertices and moving vertices of the instances `which` baked together.
struct BakeCounts {
  uint64_t triangles = 0, vertices = 0, moving = 0;
};
BakeCounts bakeCounts(const SceneSources& loaded, const std::vector<uint32_t>& which) {
  BakeCounts c;
  for (uint32_t i : which) {
    const Animation& a = loaded.sourceOf(loaded.instances[i]);
    c.triangles += a.triangleCount();
    c.vertices += a.vertexCount();
    c.moving += movingOf(loaded.instances[i], a);
  }
  return c;
}

// The bake of the instances `which` (in that order) at `times`: rest positions and triangles of
// every instance, then the moving vertices keyframe by keyframe. Each source keeps one scratch
// frame whose static entries stay at rest. The counts must fit 32 bits (checked by the callers).
Animation bakeInstances(const SceneSources& loaded, const std::vector<uint32_t>& which, const std::vector<double>& times,
                        const std::string& name) {
  const BakeCounts counts = bakeCounts(loaded, which);
  std::vector<uint32_t> indices;
  std::vector<float> rest;
  std::vector<uint32_t> moving;
  std::vector<float> motion;
  indices.reserve(std::size_t(counts.triangles) * 3);
  rest.resize(std::size_t(counts.vertices) * 3);
  moving.reserve(std::size_t(counts.moving));
  motion.resize(std::size_t(counts.moving) * 3 * times.size());
  std::map<const Animation*, std::vector<float>> scratchFrames;
  uint32_t base = 0;
  std::size_t movingBase = 0;
  const std::size_t movingPerFrame = std::size_t(counts.moving) * 3;
  for (uint32_t id : which) {
    const SceneSourceInstance& instance = loaded.instances[id];
    const Animation& a = loaded.sourceOf(instance);
    std::vector<float>& frame = scratchFrames[&a];
    if (frame.empty()) frame = a.positionsAt(a.startTime());
    for (uint32_t v : a.indices()) indices.push_back(base + v);
    auto local = [&](double t) { return instance.localTime(t, a); };
    a.positionsAt(local(times.front()), frame);
    std::copy(frame.begin(), frame.end(), rest.begin() + std::ptrdiff_t(base) * 3);
    transformPoints(instance.worldAt(times.front()), rest.data() + std::size_t(base) * 3, a.vertexCount());
    const uint64_t movingCount = movingOf(instance, a);
    if (movingCount > 0) {
      const bool all = movingCount == a.vertexCount();
      for (uint32_t m = 0; m < movingCount; ++m) moving.push_back(base + (all ? m : a.movingVertices()[m]));
      for (std::size_t k = 0; k < times.size(); ++k) {
        float* out = motion.data() + k * movingPerFrame + movingBase * 3;
        if (all) {
          a.positionsAt(local(times[k]), frame);
          std::copy(frame.begin(), frame.end(), out);
        } else {
          a.movingPositionsAt(local(times[k]), frame);
          for (uint32_t m = 0; m < movingCount; ++m)
            std::copy_n(frame.data() + 3 * std::size_t(a.movingVertices()[m]), 3, out + 3 * std::size_t(m));
        }
        transformPoints(instance.worldAt(times[k]), out, movingCount);
      }
      a.positionsAt(a.startTime(), frame);  // static entries back at rest for the next instance
    }
    base += a.vertexCount();
    movingBase += movingCount;
  }
  return Animation::withStaticVertices(std::move(indices), std::move(rest), std::move(moving), std::move(motion),
                                       std::vector<double>(times), name);
}

}  // namespace

std::vector<double> SceneSources::frameTimes() const { return bakeTimes(start, end, fps); }

SceneSources loadSceneSources(const std::string& path, const LoadOptions& options) {
  SceneSources loaded;
  loaded.description = parseScene(path, options);
  const SceneDescription& scene = loaded.description;
  {
    const SceneStackEntry entry(canonical(path));
    loadSources(options, loaded);
  }
  for (std::size_t o = 0; o < scene.objects.size(); ++o)
    for (const SceneInstance& i : scene.objects[o].instances)
      loaded.instances.push_back({uint32_t(o), loaded.objectSource[o], i.placement, i.path, i.time});
  uint64_t baked = 0;
  for (uint32_t i = 0; i < loaded.instances.size(); ++i) {
    const uint32_t count = loaded.sourceOf(loaded.instances[i]).triangleCount();
    const uint32_t first = uint32_t(std::min<uint64_t>(baked, 0xffffffffu));  // a bake past 2^32 is refused
    loaded.triangleRuns.push_back({i, 0, count, loaded.instances[i].object, i, first});
    baked += count;
  }
  std::tie(loaded.start, loaded.end) = timeRange(loaded);
  loaded.fps = options.fps > 0.0 ? options.fps : scene.fps;
  const double keyframes = bakeKeyframeCount(loaded.start, loaded.end, loaded.fps);
  if (!(keyframes < 4294967296.0)) {
    char text[160];
    std::snprintf(text, sizeof text, "the time range [%g, %g] at %g keyframes per second needs more than 2^32 keyframes",
                  loaded.start, loaded.end, loaded.fps);
    throw tsah::FileError(path, text);
  }
  loaded.frameCount = uint64_t(keyframes);
  return loaded;
}

BakedScene bakeScene(const std::string& path, const LoadOptions& options) {
  SceneSources loaded = loadSceneSources(path, options);
  BakedScene baked;
  baked.description = loaded.description;
  const SceneDescription& scene = baked.description;
  baked.distinctSources = uint32_t(loaded.sources.size());
  SceneStatement& st = baked.statement;
  st.sourceBytes = loaded.sourceBytes;

  // The statement, object by object: the first object that takes the scene past the available
  // memory is the one named in the error.
  st.keyframes = loaded.frameCount;
  st.availableBytes = tsah::availableMemoryBytes();
  uint64_t scratch = 0;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const SceneObject& object = scene.objects[o];
    const Animation& a = *loaded.sources[loaded.objectSource[o]];
    SceneObjectReport r{object.name, object.file, uint32_t(object.instances.size()), a.triangleCount(),
                        a.vertexCount(), a.keyframeCount(), object.subdivide, 0, 0, 0};
    for (const SceneInstance& i : object.instances) {
      r.triangles += a.triangleCount();
      r.vertices += a.vertexCount();
      r.movingVertices += movingOf(i, a);
    }
    st.triangles += r.triangles;
    st.vertices += r.vertices;
    st.movingVertices += r.movingVertices;
    scratch = std::max<uint64_t>(scratch, uint64_t(a.vertexCount()) * 12);
    st.animationBytes = Animation::memoryBytesFor(st.triangles, st.vertices, st.movingVertices, st.keyframes);
    // + the bake's own list of times, copied into the animation at the end.
    st.peakBytes = st.animationBytes + st.sourceBytes + scratch * scene.objects.size() + st.keyframes * 8;
    if (st.triangles > 0xffffffffull || st.vertices > 0xffffffffull)
      failObject(scene, object, std::to_string(r.instances) + " instances take the scene to " +
                                    std::to_string(st.triangles) + " triangles and " + std::to_string(st.vertices) +
                                    " vertices, more than 2^32");
    if (st.peakBytes > st.availableBytes)
      failObject(scene, object, std::to_string(r.instances) + " instances take the scene to " +
                                    std::to_string(st.triangles) + " triangles x " + std::to_string(st.keyframes) +
                                    " keyframes: the bake would need " + mib(st.peakBytes) + ", more than the " +
                                    mib(st.availableBytes) + " of memory available");
    baked.objects.push_back(std::move(r));
  }

  try {
    baked.animation = bakeInstances(loaded, allInstances(loaded), loaded.frameTimes(), scene.name);
  } catch (const tsah::FileError& e) {
    throw tsah::FileError(scene.file, std::string("invalid baked scene: ") + e.what());
  }
  return baked;
}

const SceneTriangleRun& SceneSources::runOf(uint32_t instance, uint32_t prim) const {
  // The last run starting at or before (instance, prim).
  const auto after = std::upper_bound(triangleRuns.begin(), triangleRuns.end(), std::make_pair(instance, prim),
                                      [](const std::pair<uint32_t, uint32_t>& key, const SceneTriangleRun& run) {
                                        return key < std::make_pair(run.instance, run.sourceFirst);
                                      });
  if (after == triangleRuns.begin() || std::prev(after)->instance != instance ||
      prim - std::prev(after)->sourceFirst >= std::prev(after)->count)
    throw tsah::ConfigError("triangle " + std::to_string(prim) + " of instance " + std::to_string(instance) +
                            " is not in the scene");
  return *std::prev(after);
}

uint32_t SceneSources::bakedTriangle(uint32_t instance, uint32_t prim) const {
  const SceneTriangleRun& run = runOf(instance, prim);
  return run.bakedFirst + (prim - run.sourceFirst);
}

SceneSources flattenObjects(SceneSources scene, const std::vector<uint32_t>& objects) {
  if (objects.empty()) return scene;
  const SceneDescription& description = scene.description;
  if (!scene.flattenedObjects.empty()) throw tsah::ConfigError("flattenObjects: the scene is flattened already");
  std::vector<uint8_t> flattened(description.objects.size(), 0);
  for (std::size_t k = 0; k < objects.size(); ++k) {
    if (objects[k] >= description.objects.size() || (k > 0 && objects[k] <= objects[k - 1]))
      throw tsah::ConfigError("flattenObjects: object ids must be increasing and below " +
                              std::to_string(description.objects.size()) + " (got " + std::to_string(objects[k]) + ")");
    flattened[objects[k]] = 1;
  }
  std::vector<uint32_t> kept, merged;  // instance ids
  for (uint32_t i = 0; i < scene.instances.size(); ++i) (flattened[scene.instances[i].object] ? merged : kept).push_back(i);

  // The memory statement of the merged source before it is baked.
  const BakeCounts counts = bakeCounts(scene, merged);
  const bool moves = counts.moving > 0;
  const uint64_t keyframes = moves ? scene.frameCount : 1;
  std::string names;  // the first few, for messages and the source's name
  for (std::size_t k = 0; k < std::min<std::size_t>(objects.size(), 4); ++k)
    names += (k ? ", " : "") + tsah::printable(description.objects[objects[k]].name);
  if (objects.size() > 4) names += " and " + std::to_string(objects.size() - 4) + " more";
  const std::string what = "flattening object(s) " + names + " (" + std::to_string(merged.size()) + " instances, " +
                           std::to_string(counts.triangles) + " triangles x " + std::to_string(keyframes) + " keyframes)";
  if (counts.triangles > 0xffffffffull || counts.vertices > 0xffffffffull)
    throw tsah::DataError(description.file + ": " + what + " would make more than 2^32 triangles or vertices");
  const uint64_t need = Animation::memoryBytesFor(counts.triangles, counts.vertices, counts.moving, keyframes);
  if (need > tsah::availableMemoryBytes())
    throw tsah::DataError(description.file + ": " + what + " would need " + mib(need) + ", more than the " +
                          mib(tsah::availableMemoryBytes()) + " of memory available");
  const std::vector<double> times = moves ? scene.frameTimes() : std::vector<double>{scene.start};
  Animation baked;
  try {
    baked = bakeInstances(scene, merged, times, "flattened: " + names);
  } catch (const tsah::FileError& e) {
    throw tsah::FileError(description.file, what + ": " + e.what());
  }

  SceneSources out;
  out.description = scene.description;
  out.start = scene.start;
  out.end = scene.end;
  out.fps = scene.fps;
  out.frameCount = scene.frameCount;
  out.flattenedObjects = objects;
  // The sources kept instances show, in their order, then the merged one.
  std::vector<uint8_t> stillShown(scene.sources.size(), 0);
  for (uint32_t i : kept) stillShown[scene.instances[i].source] = 1;
  std::vector<uint32_t> newSource(scene.sources.size(), UINT32_MAX);
  for (uint32_t s = 0; s < scene.sources.size(); ++s)
    if (stillShown[s]) {
      newSource[s] = uint32_t(out.sources.size());
      out.sources.push_back(scene.sources[s]);
      out.sourceBytes += scene.sources[s]->memoryBytes();
    }
  const uint32_t mergedSource = uint32_t(out.sources.size());
  out.sourceBytes += baked.memoryBytes();
  out.sources.push_back(std::make_shared<const Animation>(std::move(baked)));
  for (uint32_t o = 0; o < description.objects.size(); ++o)
    out.objectSource.push_back(flattened[o] ? mergedSource : newSource[scene.objectSource[o]]);
  for (uint32_t i : kept) {
    SceneSourceInstance instance = scene.instances[i];
    instance.source = newSource[instance.source];
    const SceneTriangleRun& run = scene.triangleRuns[i];
    out.triangleRuns.push_back({uint32_t(out.instances.size()), 0, run.count, run.object, run.originalInstance, run.bakedFirst});
    out.instances.push_back(std::move(instance));
  }
  // The merged instance: its source is already in world space and at scene time (local = t).
  SceneSourceInstance showing;
  showing.object = objects.front();
  showing.source = mergedSource;
  showing.time.offset = scene.start;
  uint32_t first = 0;
  for (uint32_t i : merged) {
    const SceneTriangleRun& run = scene.triangleRuns[i];
    out.triangleRuns.push_back({uint32_t(out.instances.size()), first, run.count, run.object, run.originalInstance, run.bakedFirst});
    first += run.count;
  }
  out.instances.push_back(std::move(showing));
  return out;
}

Animation loadScene(const std::string& path, const LoadOptions& options) {
  return std::move(bakeScene(path, options).animation);
}

}  // namespace anim
