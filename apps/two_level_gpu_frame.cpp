// The GPU frame runtime of a two-level scene (`tsah trace SCENE TREE-v3 --device cuda`): per frame
// GpuTwoLevelRuntime::updateAt (the poses' BLAS refits and the TLAS refit in one CUDA graph) and
// the device renderer through it (GpuTwoLevelRenderer), both timed with CUDA events.
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
cuda::GpuTwoLevelRuntime::Config onDevice(int gpu, cuda::TlasUpdate tlas) {
  cuda::useDevice(gpu);
  cuda::GpuTwoLevelRuntime::Config config;
  config.device = gpu;
  config.tlas = tlas;
  return config;
}

class GpuTwoLevelFrameRuntime final : public FrameRuntime {
 public:
  GpuTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, int gpu, cuda::TlasUpdate tlas)
      : scene_(std::move(scene)), gpu_(gpu), tlas_(tlas), runtime_(*scene_, onDevice(gpu, tlas)), renderer_(runtime_) {}

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
    const cuda::TwoLevelUpdateTimings t = runtime_.updateAt(time);
    FrameUpdate u;
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
           " BLAS in bvh2, " + std::to_string(scene_->instanceCount()) + " instances, TLAS " +
           (tlas_ == cuda::TlasUpdate::Refit ? std::string("refitted") : std::string("rebuilt (") + cuda::tlasUpdateName(tlas_) + ")") +
           " per frame";
  }

  void describe(nlohmann::json& out) const override {
    out["device"] = runtime_.device().name;
    out["gpu"] = deviceJson(gpu_);
    out["timer"] = "CUDA events (device time)";
    out["layout"] = "bvh2";
    out["two_level"] = describeTwoLevel(*scene_);
    out["two_level"].erase("blases");
    out["two_level"]["tlas_update"] = cuda::tlasUpdateName(tlas_);
    out["two_level"]["blas_refits"] = runtime_.blasRefits();
  }

 private:
  std::shared_ptr<const TwoLevelScene> scene_;
  int gpu_;
  cuda::TlasUpdate tlas_;
  cuda::GpuTwoLevelRuntime runtime_;
  cuda::GpuTwoLevelRenderer renderer_;
};

}  // namespace

#endif

std::unique_ptr<FrameRuntime> makeGpuTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, int gpu,
                                                          const std::string& tlas) {
  requireGpuRuntime();
#if TSAH_HAVE_CUDA
  return std::make_unique<GpuTwoLevelFrameRuntime>(std::move(scene), gpu, cuda::parseTlasUpdate(tlas));
#else
  (void)scene, (void)gpu, (void)tlas;
  return nullptr;  // requireGpuRuntime threw
#endif
}

}  // namespace tsah::cli
