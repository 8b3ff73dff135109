// tsah::cuda::GpuTwoLevelRenderer (gpu_two_level_render.hpp): the shading tables of the scene and
// the frame's buffers; the passes are two_level_render.cu's.
#include "tsah_cuda/gpu_two_level_render.hpp"

#include <span>
#include <string>

#include "anim/scene.hpp"
#include "tsah/base/error.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "kernels.hpp"
#include "two_level_render.hpp"

namespace tsah::cuda {

using detail::kRenderEvents;

struct GpuTwoLevelRenderer::Impl {
  explicit Impl(GpuTwoLevelRuntime& r);
  ~Impl() {
    if (side) cudaStreamDestroy(side);
  }

  detail::TwoLevelShadingTables tables(const detail::TlasScene& scene) const {
    detail::TwoLevelShadingTables t;
    t.scene = scene;
    t.firstTriangle = firstTriangle.data();
    t.instanceCount = uint32_t(firstTriangle.size() - 1);
    t.sourceOffsets = sourceOffsets.data();
    t.vertexTriOffsets = vertexTriOffsets.data();
    t.vertexTris = vertexTris.data();
    return t;
  }

  GpuTwoLevelRuntime& runtime;
  cudaStream_t side = nullptr;  // the shadow pass, beside the AO pass on the runtime's stream
  detail::EventTimer events;
  DeviceBuffer<uint32_t> firstTriangle, sourceOffsets, vertexTriOffsets, vertexTris;
  detail::PassBufferSet passes;
  detail::Frame last{};  // the last rendered frame (downloadSurfaces)
  bool rendered = false;
};

GpuTwoLevelRenderer::Impl::Impl(GpuTwoLevelRuntime& r) : runtime(r) {
  const anim::SceneSources& scene = runtime.scene().scene;
  std::vector<uint32_t> first, sourceFirst;
  uint64_t triangles = 0;
  for (const anim::SceneSourceInstance& instance : scene.instances) {
    first.push_back(uint32_t(triangles));
    triangles += scene.sourceOf(instance).triangleCount();
    if (triangles >= kNoHit)
      throw DataError(scene.description.file + ": more than 2^32 triangles in the world mesh to shade");
  }
  first.push_back(uint32_t(triangles));
  // Per source, the triangles of each vertex (CSR), increasing: the order the CPU renderer sums in.
  std::vector<uint32_t> offsets, tris, sourceOffset;
  for (const auto& source : scene.sources) {
    sourceOffset.push_back(uint32_t(offsets.size()));
    const std::span<const uint32_t> indices = source->indices();
    if (tris.size() + indices.size() >= kNoHit)
      throw DataError(scene.description.file + ": more than 2^32 triangle corners in the scene's sources");
    const detail::VertexTriangles lists = detail::vertexTriangles(indices, source->vertexCount());
    const auto base = uint32_t(tris.size());
    tris.insert(tris.end(), lists.triangles.begin(), lists.triangles.end());
    for (uint32_t c : lists.offsets) offsets.push_back(base + c);
  }
  for (const anim::SceneSourceInstance& instance : scene.instances) sourceFirst.push_back(sourceOffset[instance.source]);
  firstTriangle = DeviceBuffer<uint32_t>(std::span<const uint32_t>(first));
  sourceOffsets = DeviceBuffer<uint32_t>(std::span<const uint32_t>(sourceFirst));
  vertexTriOffsets = DeviceBuffer<uint32_t>(std::span<const uint32_t>(offsets));
  vertexTris = DeviceBuffer<uint32_t>(std::span<const uint32_t>(tris));
  CUDA_CHECK(cudaStreamCreateWithFlags(&side, cudaStreamNonBlocking));
  events.create(kRenderEvents);
  CUDA_CHECK(cudaDeviceSynchronize());
}

GpuTwoLevelRenderer::GpuTwoLevelRenderer(GpuTwoLevelRuntime& runtime) : impl_(std::make_unique<Impl>(runtime)) {}

GpuTwoLevelRenderer::~GpuTwoLevelRenderer() = default;

RenderStats GpuTwoLevelRenderer::render(const Camera& camera, const SceneLighting& lighting,
                                        const RenderSettings& settings, Image* image, GpuRenderTimings* timings) {
  Impl& m = *impl_;
  uint64_t aoRays = 0, shadowRays = 0;
  const detail::Frame f = detail::makeFrame(camera, lighting, settings, aoRays, shadowRays);
  const detail::TwoLevelTraceAccess access = m.runtime.traceAccess();
  const detail::PassBuffers b = m.passes.startFrame(f, aoRays, shadowRays, true, access.stream, m.side, m.events);
  m.last = f;
  m.rendered = true;
  return detail::renderTwoLevelFrame(b, f, m.tables(access.scene), access.blurred, aoRays, shadowRays, image, timings);
}

std::vector<Surface> GpuTwoLevelRenderer::downloadSurfaces() const {
  const Impl& m = *impl_;
  if (!m.rendered) throw ConfigError("GPU two-level renderer: no frame rendered yet");
  const detail::Frame& f = m.last;
  DeviceBuffer<Surface> out(std::size_t(f.width) * f.height);
  cudaStream_t stream = m.runtime.traceAccess().stream;
  detail::launchUnpackSurfaces(f, m.passes.surfaces(), out.data(), stream);
  return out.download(stream);
}

}  // namespace tsah::cuda
