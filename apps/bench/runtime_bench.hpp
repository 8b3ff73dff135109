#pragma once
// The runtime half of the benchmark (the paper's Table 2, Figures 5 and 6): every frame is updated
// (refit of one tree, or of the tree of the frame's segment, or a rebuild) and traced with the
// renderer's workload (1 primary, N ambient-occlusion and M shadow rays per pixel), on the CPU
// (CpuRuntime + renderFrame) or on the GPU (GpuRuntime + renderFrameGpu, when built with CUDA).
// The CPU side also runs the Embree peer on the same frames and rays.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/io/tree_set.hpp"

namespace tsah::cli {
class FrameRuntime;
}

namespace tsah::bench {

struct BatchTrace;

// What every runtime method traces: the frames, the view and the ray workload.
struct RuntimeSetup {
  std::vector<double> times;                     // animation time of each traced frame
  std::function<Camera(double time)> camera;     // the camera at a time
  SceneLighting lighting;
  RenderSettings settings;                       // image size, AO/shadow rays, seed (frame is set per frame)
  unsigned threads = 0;                          // CPU worker threads (0: all cores)
  int gpu = 0;                                   // GPU: the device the method runs on
  Layout layout = fastestLayout();            // CPU: the layout every refit and rebuild traces
  WideCollapser::Config collapse;                // wide layouts (CPU, GPU cwbvh): cost constants, k, leaf size
  std::function<void(const std::string&)> progress;
};

// One frame of one method.
struct FrameTiming {
  double time = 0.0;
  double updateMs = 0.0;  // interpolation + refit + Woop, or interpolation + rebuild (+ refit/Woop)
  double traceMs = 0.0;   // the three ray passes
  double totalMs = 0.0;   // CPU: update + trace; GPU: update + the whole rendered frame on the device
  RenderStats rays;       // rays and milliseconds per pass
};

// One row of Table 2 (or of the Embree comparison).
struct RuntimeMethod {
  std::string name;   // sah0, sahstar, tsah0, tsah0-seg3, rebuild-sweep, rebuild-binned, lbvh, hlbvh-sah, embree-*
  std::string label;  // as the report prints it
  std::string update; // "refit" or "rebuild"
  std::vector<FrameTiming> frames;
  nlohmann::json extra = nlohmann::json::object();  // method-specific figures (agreement with the toolkit, ...)
};

// The JSON of a method: name, label, update, average {update_ms, trace_ms, total_ms, mrays_per_s
// {primary, ao, shadow, total}, rays_per_frame {...}} (times: means over frames; rates: all rays of
// a type over all time spent on that type) and per_frame arrays (time, update_ms, trace_ms,
// total_ms, mrays_per_s).
nlohmann::json toJson(const RuntimeMethod& method);

// Trees a refit method traces: one tree for the whole animation, or a tree set (one runtime that
// refits the tree of each frame's part, tsah::treeIndexAt).
struct RefitTrees {
  std::string name, label;
  std::vector<const Bvh*> trees;   // one, or one per part
  std::vector<TimeRange> ranges;   // empty for a single tree, else each tree's time range
};

// The trees as a tsah::TreeSet (a single tree gets the animation's range).
TreeSet treeSetOf(const RefitTrees& trees, const anim::Animation& animation);

enum class CpuRebuild { Sweep, Binned };

// One runtime method on the CPU: the refit of its tree(s), or a rebuild every frame.
struct CpuMethodSpec {
  RefitTrees trees;                   // refit: one tree or the segment trees; rebuild: trees[0] starts
  std::optional<CpuRebuild> rebuild;  // set: a new tree every frame (sweep SAH + leaf collapse, or binned SAH)
};

// CPU: per frame and method interpolate, refit (+ Woop) or rebuild, then renderFrame. The methods
// run frame by frame, all of them on a frame before the next (in an order rotated every frame),
// so a machine whose load changes during the run (other jobs) slows every method alike instead of
// whichever happened to run then. When image is given, the frame imageFrame of method imageMethod
// is kept in it.
std::vector<RuntimeMethod> runCpuMethods(const anim::Animation& animation, const std::vector<CpuMethodSpec>& methods,
                                         const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup,
                                         Image* image = nullptr, std::size_t imageMethod = 0, uint32_t imageFrame = 0);

// The toolkit's CPU runtime of `tree` for the animation's triangles, in `layout` (setup's threads
// and collapse).
std::unique_ptr<CpuRuntime> makeRuntime(const anim::Animation& animation, const Bvh& tree, const RuntimeSetup& setup,
                                        Layout layout);

// CPU peer: the toolkit's CPU runtime refitting `tree`, in every layout the processor supports
// (setup.layout first, then bvh8, bvh4, bvh2: methods NAME-bvhN, extra.layout describing the tree
// and its kernels), against Embree (a rebuild per frame with medium and high quality, and refit),
// all on the same frames and the same rays (made once per frame with makeRayBatch from the
// toolkit's refitted tree in setup.layout). Every method after the first has in its extra how
// many primary hits, AO and shadow occlusions differ from the first's. With a tree set (`set`,
// several trees), one more toolkit method in setup.layout refits and traces the tree of each
// frame's part (named set->name, after the single-tree layouts). Empty when the bench was built
// without Embree.
std::vector<RuntimeMethod> runEmbreeComparison(const anim::Animation& animation, const Bvh& tree,
                                               const std::string& name, const std::string& label,
                                               const RuntimeSetup& setup, const RefitTrees* set = nullptr);

// GPU (built with CUDA): per frame GpuRuntime::updateAt (interpolation, refit, Woop on the device)
// and renderFrameGpu. Throws tsah::ConfigError when the bench was built without CUDA,
// tsah::Failure when no device exists.
// layout: "bvh2" or "cwbvh" (GpuRuntime::Config::layout), empty for the runtime's default.
RuntimeMethod runGpuRefit(const anim::Animation& animation, const RefitTrees& trees, const RuntimeSetup& setup,
                          Image* image = nullptr, uint32_t imageFrame = 0, const std::string& layout = {});
// GPU: per frame GpuRuntime::rebuildAt (lbvh or hlbvh-sah, collapse to maxLeaf, Woop) and renderFrameGpu.
// layout as runGpuRefit: with cwbvh every rebuilt tree is converted to the compressed layout on the
// device (leaves of at most 8), the conversion counted in the update (extra.wide_conversion_ms).
RuntimeMethod runGpuRebuild(const anim::Animation& animation, const Bvh& initialTree, const std::string& method,
                            const CostModel& cost, uint32_t maxLeaf, const RuntimeSetup& setup,
                            const std::string& layout = {});
// A frame of batch-traced rays (ray_batch.hpp): its update and the batch's passes.
FrameTiming frameOf(double time, double updateMs, const BatchTrace& trace);
// Over a method's frames: the mean frame total, and the trace rate of all its rays (MRays/s).
double averageTotalMs(const RuntimeMethod& m);
double traceRate(const RuntimeMethod& m);

// One frame of a method after its update (updateMs): the ray passes timed (rays, traceMs) and the
// whole frame (totalMs = updateMs + the driver's frame time); with `image`, the frame is rendered
// once more, untimed, into it (the GPU downloads the picture only then).
FrameTiming timeFrame(cli::FrameRuntime& runtime, const RuntimeSetup& setup, double time, double updateMs,
                      const RenderSettings& settings, Image* image);
// Progress on the first, every tenth and the last frame: "LABEL: frame F/N".
void reportFrame(const RuntimeSetup& setup, const std::string& label, std::size_t frame);

}  // namespace tsah::bench
