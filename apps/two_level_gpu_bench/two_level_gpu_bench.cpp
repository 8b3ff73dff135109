// tsah_two_level_gpu_bench: the GPU two-level runtime (tsah_cuda/gpu_two_level.hpp) per frame.
//   tsah_two_level_gpu_bench SCENE.json [--tree TREE.tbvh | --save-tree TREE.tbvh [--build-only]]
//                            [--frames 50] [--width 1024] [--height 768]
//                            [--ao 4] [--k 2] [--build-frames 5] [--no-rebuild-reference]
//                            [--global-refits] [--refit-part-leaves 512] [--no-phase-timings]
//                            [--flat-tree FLAT.tbvh] [--tlas refit|lbvh|hlbvh-sah|all] [--layout bvh2|cwbvh]
// Builds the two-level structure (or loads a version 3 .tbvh built for the scene), then for each of
// --frames times spread over the scene's time range: updateAt (upload of the instance transforms,
// BLAS refits, TLAS refit: CUDA events), then primary rays (a camera fitted to the instances' boxes,
// one ray per pixel: closest hit) and --ao occlusion rays per primary hit (cosine-distributed
// around the reversed primary ray, from the hit point, 10% of the scene's diagonal long: any hit).
// The TLAS rebuild reference is tsah::rebuildTlas on the host over the frame's instance boxes
// (wall clock). --tlas (default all): the GPU TLAS updates compared on the same rays, each on its
// own runtime (GpuTwoLevelRuntime::Config::tlas): the T-SAH TLAS refitted (always run; the
// top-level fields are its) and the TLAS rebuilt every frame over the instance boxes by LBVH and/or
// HLBVH-SAH; per update its TLAS time, update, primary and AO times and the frame total, and the
// hits that differ from the refit's. The scene's data: paths resolve as `tsah` resolves them ($TSAH_DATA_DIR, archives
// and .xz files unpacked into the cache). --flat-tree: a flat tree of the same scene (tsah optimize --structure flat), whose
// GPU runtime (the baked scene, in the same layout) updates at the same times and traces the same rays
// (the trace-rate comparison). --layout: the BLAS layout (GpuTwoLevelRuntime::Config::layout) and
// the flat runtime's (cwbvh: collapsed with the flat tree's objective). Prints one JSON object
// (per-frame values and medians).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>

#include "anim/load_options.hpp"
#include "anim/scene.hpp"
#include "bench/data_scan.hpp"
#include "tsah/base/error.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"

namespace {

struct Options {
  std::string scene, tree, saveTree, flatTree;
  uint32_t frames = 50, width = 1024, height = 768, ao = 4, buildFrames = 5;
  int k = 2;
  bool rebuildReference = true;
  bool buildOnly = false;  // build and save (--save-tree), no device needed
  bool keyedPoses = true;   // GpuTwoLevelRuntime::Config::keyedPoses
  bool blockRefits = true;  // GpuTwoLevelRuntime::Config::blockRefits
  uint32_t refitPartLeaves = tsah::cuda::GpuTwoLevelRuntime::Config{}.refitPartLeaves;
  bool phaseTimings = true;  // GpuTwoLevelRuntime::Config::phaseTimings
  std::string tlas = "all";  // refit, lbvh, hlbvh-sah or all
  std::string layout = "bvh2";  // bvh2 or cwbvh
};

// One TLAS update compared (--tlas): its runtime and per-frame figures.
struct TlasRun {
  tsah::cuda::TlasUpdate update = tsah::cuda::TlasUpdate::Refit;
  std::unique_ptr<tsah::cuda::GpuTwoLevelRuntime> gpu;
  std::vector<double> tlasMs, rebuildMs, updateMs, primaryMs, aoMs, frameMs;
  uint64_t primaryHits = 0, primaryMismatches = 0, aoMismatches = 0;
  uint32_t tlasNodes = 0;  // the TLAS's interior nodes at the last timed frame
};

// The updates --tlas names: the refit always first (the reference of the others).
std::vector<tsah::cuda::TlasUpdate> tlasUpdates(const std::string& name) {
  using tsah::cuda::TlasUpdate;
  if (name == "all") return {TlasUpdate::Refit, TlasUpdate::Lbvh, TlasUpdate::HlbvhSah};
  const TlasUpdate u = tsah::cuda::parseTlasUpdate(name);
  if (u == TlasUpdate::Refit) return {u};
  return {TlasUpdate::Refit, u};
}

bool sameHit(const tsah::TwoLevelHit& a, const tsah::TwoLevelHit& b) {
  return a.valid() == b.valid() && (!a.valid() || (a.instance == b.instance && a.prim == b.prim));
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::vector<tsah::Ray> primaryRays(const tsah::Camera& camera, uint32_t width, uint32_t height) {
  const tsah::CameraRays gen = tsah::cameraRays(camera, width, height);
  std::vector<tsah::Ray> rays;
  rays.reserve(std::size_t(width) * height);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x) rays.push_back(gen.ray(float(x) + 0.5f, float(y) + 0.5f));
  return rays;
}

std::vector<tsah::Ray> occlusionRays(std::span<const tsah::Ray> primary, std::span<const tsah::TwoLevelHit> hits,
                                     uint32_t perHit, float length, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<tsah::Ray> rays;
  for (std::size_t i = 0; i < primary.size(); ++i) {
    if (!hits[i].valid()) continue;
    const tsah::Ray& p = primary[i];
    const tsah::Vec3 back = tsah::normalize(p.dir * -1.0f);
    const tsah::Vec3 at = p.org + p.dir * (hits[i].t * 0.9999f);
    for (uint32_t k = 0; k < perHit; ++k) {
      tsah::Ray r;
      r.org = at;
      r.dir = tsah::cosineHemisphere(back, unit(rng), unit(rng));
      r.tmin = 0.0f;
      r.tmax = length;
      rays.push_back(r);
    }
  }
  return rays;
}

int run(const Options& opt) {
  // Scenes' data: paths as `tsah` resolves them ($TSAH_DATA_DIR, archives and .xz files unpacked
  // into $TSAH_CACHE_DIR or the user's cache).
  anim::LoadOptions load;
  load.resolveDataPath = tsah::bench::dataPathResolver({}, {}, {});
  tsah::TreeOptions build;
  build.objective.k = opt.k;
  build.frames = opt.buildFrames;
  const tsah::TwoLevelScene scene =
      opt.tree.empty() ? tsah::loadTwoLevelScene(opt.scene, load, build)
                       : tsah::loadTwoLevelSceneFile(opt.tree, anim::loadSceneSources(opt.scene, load));
  if (!opt.saveTree.empty()) tsah::saveTwoLevelScene(opt.saveTree, scene);
  if (opt.buildOnly) return 0;
  const tsah::Layout layout = tsah::parse<tsah::Layout>(opt.layout);
  std::vector<TlasRun> runs;
  for (tsah::cuda::TlasUpdate update : tlasUpdates(opt.tlas)) {
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.keyedPoses = opt.keyedPoses;
    config.blockRefits = opt.blockRefits;
    config.refitPartLeaves = opt.refitPartLeaves;
    config.phaseTimings = opt.phaseTimings;
    config.tlas = update;
    config.layout = layout;
    TlasRun& r = runs.emplace_back();
    r.update = update;
    r.gpu = std::make_unique<tsah::cuda::GpuTwoLevelRuntime>(scene, config);
  }
  tsah::cuda::GpuTwoLevelRuntime& gpu = *runs.front().gpu;  // the refit: the top-level fields
  // The flat reference: the baked scene and its tree on the GPU runtime.
  std::unique_ptr<anim::Animation> baked;
  std::unique_ptr<tsah::cuda::GpuRuntime> flat;
  if (!opt.flatTree.empty()) {
    baked = std::make_unique<anim::Animation>(anim::loadScene(opt.scene, load));
    const tsah::BvhFile flatFile = tsah::loadBvhFile(opt.flatTree);
    tsah::cuda::GpuRuntime::Config config;
    config.layout = layout;
    config.wideObjective = flatFile.info.objective;
    flat = std::make_unique<tsah::cuda::GpuRuntime>(tsah::flattenBvh(flatFile.bvh), *baked, config);
  }
  const double start = scene.frameTimes.empty() ? scene.scene.start : scene.frameTimes.front();
  const double end = scene.frameTimes.empty() ? start : scene.frameTimes.back();
  tsah::Aabb all;
  for (const tsah::Aabb& b : scene.instanceBoxes.boxes) all.extend(b);
  const tsah::Camera camera = tsah::fitCamera(all, {0, 1, 0}, 45.0f, float(opt.width) / float(opt.height));
  const std::vector<tsah::Ray> primary = primaryRays(camera, opt.width, opt.height);
  const tsah::Vec3 e = all.extent();
  const float aoLength = 0.1f * std::sqrt(e.x * e.x + e.y * e.y + e.z * e.z);

  std::vector<double> upload, blas, tlas, update, primaryMs, aoMs, rebuildMs, refits, flatUpdate, flatPrimary, flatAo;
  uint64_t hitCount = 0, flatHitCount = 0;
  nlohmann::json frames = nlohmann::json::array();
  for (uint32_t f = 0; f < opt.frames; ++f) {
    const double t = opt.frames > 1 ? start + (end - start) * double(f) / double(opt.frames - 1) : start;
    const tsah::cuda::TwoLevelUpdateTimings u = gpu.updateAt(t);
    tsah::RayPassStats ps, as;
    const std::vector<tsah::TwoLevelHit> hits = gpu.closestHits(primary, &ps);
    const std::vector<tsah::Ray> ao = occlusionRays(primary, hits, opt.ao, aoLength, f + 1);
    const std::vector<uint8_t> occluded = gpu.anyHits(ao, &as);
    for (const tsah::TwoLevelHit& h : hits) hitCount += h.valid() ? 1 : 0;
    // Every TLAS update on the refit's rays (the refit's own figures are the ones above).
    nlohmann::json perUpdate = nlohmann::json::object();
    for (TlasRun& r : runs) {
      tsah::cuda::TwoLevelUpdateTimings ru = u;
      tsah::RayPassStats rp = ps, ra = as;
      if (r.gpu.get() != &gpu) {
        ru = r.gpu->updateAt(t);
        const std::vector<tsah::TwoLevelHit> rh = r.gpu->closestHits(primary, &rp);
        const std::vector<uint8_t> ro = r.gpu->anyHits(ao, &ra);
        for (std::size_t i = 0; i < rh.size(); ++i) r.primaryMismatches += sameHit(rh[i], hits[i]) ? 0 : 1;
        for (std::size_t i = 0; i < ro.size(); ++i) r.aoMismatches += (ro[i] != 0) == (occluded[i] != 0) ? 0 : 1;
        for (const tsah::TwoLevelHit& h : rh) r.primaryHits += h.valid() ? 1 : 0;
      } else {
        for (const tsah::TwoLevelHit& h : hits) r.primaryHits += h.valid() ? 1 : 0;
      }
      const double frameMs = ru.totalMs() + rp.ms + ra.ms;
      r.tlasMs.push_back(ru.tlasMs);
      r.rebuildMs.push_back(ru.tlasRebuildMs);
      r.updateMs.push_back(ru.totalMs());
      r.primaryMs.push_back(rp.ms);
      r.aoMs.push_back(ra.ms);
      r.frameMs.push_back(frameMs);
      r.tlasNodes = ru.tlasNodes;
      perUpdate[tsah::cuda::tlasUpdateName(r.update)] = {{"tlas_update_ms", ru.tlasMs}, {"tlas_rebuild_ms", ru.tlasRebuildMs},
                                                         {"update_ms", ru.totalMs()}, {"primary_ms", rp.ms},
                                                         {"ao_ms", ra.ms}, {"frame_ms", frameMs}};
    }
    if (flat) {
      tsah::RayPassStats fp, fa;
      flatUpdate.push_back(flat->updateAt(t).totalMs());
      for (const tsah::Hit& h : flat->closestHits(primary, &fp)) flatHitCount += h.valid() ? 1 : 0;
      flat->anyHits(ao, &fa);
      flatPrimary.push_back(fp.ms);
      flatAo.push_back(fa.ms);
    }
    double rebuild = 0.0;
    if (opt.rebuildReference) {
      const std::vector<tsah::Aabb> boxes = gpu.downloadInstanceBoxes();
      const auto t0 = std::chrono::steady_clock::now();
      const tsah::Bvh rebuilt = tsah::rebuildTlas(boxes, scene.objective);
      rebuild = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      (void)rebuilt;
    }
    upload.push_back(u.uploadMs);
    blas.push_back(u.blasMs);
    tlas.push_back(u.tlasMs);
    update.push_back(u.totalMs());
    primaryMs.push_back(ps.ms);
    aoMs.push_back(as.ms);
    rebuildMs.push_back(rebuild);
    refits.push_back(u.blasRefits);
    frames.push_back({{"time", t}, {"upload_ms", u.uploadMs}, {"blas_refit_ms", u.blasMs}, {"tlas_update_ms", u.tlasMs},
                      {"update_ms", u.totalMs()}, {"blas_refits", u.blasRefits}, {"primary_rays", ps.rays},
                      {"primary_ms", ps.ms}, {"ao_rays", as.rays}, {"ao_ms", as.ms},
                      {"tlas_rebuild_cpu_ms", rebuild}, {"tlas", perUpdate}});
  }
  nlohmann::json j;
  j["scene"] = opt.scene;
  j["tree"] = opt.tree;
  j["device"] = gpu.device().name;
  j["layout"] = opt.layout;
  j["instances"] = scene.instanceCount();
  j["blas"] = scene.blases.size();
  j["poses"] = scene.poses.size();
  j["tlas_interior_nodes"] = runs.front().tlasNodes;
  j["image"] = {opt.width, opt.height};
  j["ao_per_hit"] = opt.ao;
  j["keyed_poses"] = opt.keyedPoses;
  j["key_box_bytes"] = gpu.keyBoxBytes();
  j["block_refits"] = opt.blockRefits;
  j["refit_part_leaves"] = opt.refitPartLeaves;
  j["phase_timings"] = opt.phaseTimings;
  j["median"] = {{"upload_ms", median(upload)}, {"blas_refit_ms", median(blas)}, {"tlas_update_ms", median(tlas)},
                 {"update_ms", median(update)}, {"primary_ms", median(primaryMs)}, {"ao_ms", median(aoMs)},
                 {"tlas_rebuild_cpu_ms", median(rebuildMs)}, {"blas_refits", median(refits)}};
  // The TLAS updates compared, the refit first: medians over the frames (frame_ms: update + primary
  // + AO of each frame), the TLAS size at the last timed frame, and the hits that differ from the
  // refit's.
  nlohmann::json tlasRuns = nlohmann::json::array();
  for (TlasRun& r : runs)
    tlasRuns.push_back({{"update", tsah::cuda::tlasUpdateName(r.update)},
                        {"median", {{"tlas_update_ms", median(r.tlasMs)}, {"tlas_rebuild_ms", median(r.rebuildMs)},
                                    {"update_ms", median(r.updateMs)}, {"primary_ms", median(r.primaryMs)},
                                    {"ao_ms", median(r.aoMs)}, {"frame_ms", median(r.frameMs)}}},
                        {"tlas_interior_nodes", r.tlasNodes},
                        {"primary_hits", r.primaryHits},
                        {"primary_hits_unlike_refit", r.primaryMismatches},
                        {"ao_results_unlike_refit", r.aoMismatches}});
  j["tlas"] = tlasRuns;
  if (flat) {
    const double flatTrace = median(flatPrimary) + median(flatAo), twoLevelTrace = median(primaryMs) + median(aoMs);
    j["flat"] = {{"tree", opt.flatTree},
                 {"layout", opt.layout},
                 {"median", {{"update_ms", median(flatUpdate)}, {"primary_ms", median(flatPrimary)}, {"ao_ms", median(flatAo)}}},
                 {"primary_hits", flatHitCount},
                 {"two_level_primary_hits", hitCount},
                 {"trace_rate_two_level_over_flat", twoLevelTrace > 0.0 ? flatTrace / twoLevelTrace : 0.0}};
  }
  j["frames"] = frames;
  std::cout << j.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"The GPU two-level runtime per frame: update (BLAS refits, TLAS refit or rebuild) and trace times, JSON"};
  Options opt;
  bool noRebuild = false, globalRefits = false;
  app.add_option("scene", opt.scene, "Scene file (JSON)")->required();
  app.add_option("--tree", opt.tree, "A version 3 .tbvh built for the scene (default: build it)");
  app.add_option("--frames", opt.frames, "Frames timed, spread over the scene's time range (default 50)")
      ->check(CLI::Range(1u, 100000u));
  app.add_option("--width", opt.width, "Image width (default 1024)")->check(CLI::Range(1u, 16384u));
  app.add_option("--height", opt.height, "Image height (default 768)")->check(CLI::Range(1u, 16384u));
  app.add_option("--ao", opt.ao, "Occlusion rays per primary hit (default 4)")->check(CLI::Range(0u, 64u));
  app.add_option("--k", opt.k, "T-SAH k of the built trees (default 2)")->check(CLI::Range(0, 1000));
  app.add_option("--save-tree", opt.saveTree, "Save the built structure (.tbvh version 3) for later --tree runs");
  app.add_option("--build-frames", opt.buildFrames, "Representative frames per animated source (default 5)")
      ->check(CLI::Range(1u, 1000u));
  app.add_flag("--build-only", opt.buildOnly, "Only build the structure (and save it with --save-tree): no device needed");
  app.add_flag("--no-rebuild-reference", noRebuild, "Skip the per-frame host TLAS rebuild reference");
  app.add_option("--flat-tree", opt.flatTree,
                 "A flat tree of the scene (tsah optimize --structure flat): traced on the same rays for comparison");
  app.add_option("--tlas", opt.tlas,
                 "TLAS updates compared on the same rays: refit, lbvh, hlbvh-sah (each with the refit) or all "
                 "(default)")
      ->check(CLI::IsMember({"refit", "lbvh", "hlbvh-sah", "all"}));
  app.add_option("--layout", opt.layout, "BLAS layout, and the flat tree's: bvh2 (default) or cwbvh")
      ->check(CLI::IsMember({"bvh2", "cwbvh"}));
  app.add_flag("--global-refits", globalRefits,
               "Refit every tree by the global-memory walk, not by blocks in shared memory (the reference)");
  app.add_option("--refit-part-leaves", opt.refitPartLeaves,
                 "Block refits: each pose's tree split into subtrees of at most this many leaves (default 512)")
      ->check(CLI::Range(2u, 1u << 30));
  bool refitPoses = false;
  app.add_flag("--refit-poses", refitPoses,
               "Refit every pose's BLAS from its positions, not lerp its boxes from its source's key boxes");
  bool noPhaseTimings = false;
  app.add_flag("--no-phase-timings", noPhaseTimings,
               "Time the update by its start and end only (no event nodes between its phases in the graph: "
               "upload_ms and tlas_update_ms 0, blas_refit_ms the whole update)");
  CLI11_PARSE(app, argc, argv);
  opt.phaseTimings = !noPhaseTimings;
  opt.rebuildReference = !noRebuild;
  opt.blockRefits = !globalRefits;
  opt.keyedPoses = !refitPoses;
  try {
    return run(opt);
  } catch (const tsah::ConfigError& e) {
    std::cerr << "tsah_two_level_gpu_bench: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "tsah_two_level_gpu_bench: " << e.what() << "\n";
    return 1;
  }
}
