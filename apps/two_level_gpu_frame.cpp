// The GPU frame runtime of a two-level scene (`tsah trace SCENE TREE-v3 --device cuda`): per frame
// GpuTwoLevelRuntime::updateAt (the poses' BLAS refits and the TLAS refit in one CUDA graph), or with
// a shutter GpuTwoLevelRuntime::updateShutter, and the device renderer through it
// (GpuTwoLevelRenderer), timed with CUDA events (a blurred frame's update: host wall time, as it
// waits for the device between its steps).
#include <algorithm>
#include <chrono>
#include <string>

#include "tsah/base/error.hpp"
#include "two_level_cli.hpp"

#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "tsah_cuda/gpu_two_level_render.hpp"
#endif

namespace tsah::cli {

#if TSAH_HAVE_CUDA
namespace {

// The scene's runtime on GPU `gpu` (made current first: the runtime allocates on the current device).
cuda::GpuTwoLevelRuntime::Config onDevice(int gpu, Layout layout, cuda::TlasUpdate tlas) {
  cuda::useDevice(gpu);
  cuda::GpuTwoLevelRuntime::Config config;
  config.device = gpu;
  config.layout = layout;  // the runtime takes auto as bvh2
  config.tlas = tlas;
  return config;
}

class GpuTwoLevelFrameRuntime final : public FrameRuntime {
 public:
  GpuTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, int gpu, Layout layout, cuda::TlasUpdate tlas,
                          Shutter shutter, double frameInterval)
      : scene_(std::move(scene)),
        gpu_(gpu),
        layout_(gpuLayout(layout)),
        tlas_(tlas),
        shutter_(shutter),
        frameInterval_(frameInterval),
        runtime_(*scene_, onDevice(gpu, layout, tlas)),
        renderer_(runtime_) {}

  // The runtime's GPU current while it is released.
  ~GpuTwoLevelFrameRuntime() override { cuda::useDevice(gpu_); }

  // The construction updated to the first scene frame (the graph with the BLAS refits); a second
  // update at the same time captures the graph without them, and one render allocates the frame's
  // buffers and loads the kernels.
  void warmUp(double firstTime, const std::function<Camera(double)>& cameraAt, const SceneLighting& lighting,
              const RenderSettings& settings) override {
    update(firstTime);
    update(firstTime);
    cuda::useDevice(gpu_);
    renderer_.render(cameraAt(firstTime), lighting, settings, nullptr);
  }

  // The update's device time: the upload of the instance table and pose blends, the poses'
  // interpolation, refit and Woop pass, the instance boxes and the TLAS refit or rebuild (refitMs:
  // the last two parts, updateMs: all three; buildMs: the TLAS rebuild alone).
  FrameUpdate update(double time) override {
    cuda::useDevice(gpu_);
    FrameUpdate u;
    if (shutter_.fraction > 0.0) {
      const auto [open, close] = shutterInterval(scene_->scene.start, scene_->scene.end, time, frameInterval_, shutter_);
      const auto start = std::chrono::steady_clock::now();
      runtime_.updateShutter(open, close);
      u.refitMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      u.updateMs = u.refitMs;
      u.keys = std::max<uint32_t>(1, uint32_t(runtime_.keyTimes().size()));
      return u;
    }
    const cuda::TwoLevelUpdateTimings t = runtime_.updateAt(time);
    u.refitMs = t.blasMs + t.tlasMs;
    u.buildMs = t.tlasRebuildMs;
    u.updateMs = t.totalMs();
    return u;
  }

  FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                     Image* image) override {
    cuda::useDevice(gpu_);
    cuda::GpuRenderTimings timings;
    FrameRender r;
    r.rays = renderer_.render(camera, lighting, settings, image, &timings);
    r.frameMs = timings.totalMs;
    return r;
  }

  uint32_t currentTree() const override { return 0; }

  std::string summary() const override {
    return "GPU " + runtime_.device().name + ", two-level: " + std::to_string(scene_->blases.size()) +
           " BLAS in " + name(layout_) + ", " + std::to_string(scene_->instanceCount()) + " instances, TLAS " +
           (tlas_ == cuda::TlasUpdate::Refit ? std::string("refitted") : std::string("rebuilt (") + cuda::tlasUpdateName(tlas_) + ")") +
           " per frame";
  }

  void describe(nlohmann::json& out) const override {
    out["device"] = runtime_.device().name;
    out["gpu"] = deviceJson(gpu_);
    out["timer"] = shutter_.fraction > 0.0 ? "CUDA events (device time); updates: host wall time"
                                           : "CUDA events (device time)";
    out["layout"] = name(layout_);
    out["two_level"] = describeTwoLevel(*scene_);
    out["two_level"].erase("blases");
    out["two_level"]["tlas_update"] = cuda::tlasUpdateName(tlas_);
    out["two_level"]["blas_refits"] = runtime_.blasRefits();
  }

 private:
  std::shared_ptr<const TwoLevelScene> scene_;
  int gpu_;
  Layout layout_;
  cuda::TlasUpdate tlas_;
  Shutter shutter_;
  double frameInterval_ = 0.0;
  cuda::GpuTwoLevelRuntime runtime_;
  cuda::GpuTwoLevelRenderer renderer_;
};

}  // namespace

#endif

std::unique_ptr<FrameRuntime> makeGpuTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, int gpu,
                                                          Layout layout, const std::string& tlas, Shutter shutter,
                                                          double frameInterval) {
  requireGpuRuntime();
#if TSAH_HAVE_CUDA
  return std::make_unique<GpuTwoLevelFrameRuntime>(std::move(scene), gpu, layout, cuda::parseTlasUpdate(tlas), shutter,
                                                   frameInterval);
#else
  (void)scene, (void)gpu, (void)layout, (void)tlas, (void)shutter, (void)frameInterval;
  return nullptr;  // requireGpuRuntime threw
#endif
}

}  // namespace tsah::cli
