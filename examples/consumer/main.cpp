// Uses the installed tsah library: loads an animation, optimizes one T-SAH tree for all of its
// frames, writes and reads it as .tbvh, refits it to the middle frame and traces a few rays (on the
// CPU, and on the GPU too when tsah was built with CUDA and a device is present).
// usage: tsah_consumer ANIMATION OUT.tbvh
#include <cstdio>
#include <exception>
#include <vector>

#include <anim/load.hpp>
#include <tsah/io/bvh_file.hpp>
#include <tsah/runtime/cpu_runtime.hpp>
#include <tsah/pipeline.hpp>
#if defined(CONSUMER_WITH_CUDA)
#include <tsah_cuda/device.hpp>
#include <tsah_cuda/gpu_runtime.hpp>
#endif

int main(int argc, char** argv) try {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s ANIMATION OUT.tbvh\n", argv[0]);
    return 2;
  }
  const anim::Animation animation = anim::load(argv[1]);
  const tsah::TreeOptions options;  // T-SAH, 5 representative frames, seed 1: `tsah optimize`'s defaults
  const tsah::OptimizedTree tree = tsah::optimizeAnimation(animation, options);
  tsah::saveBvhFile(argv[2], tree.bvh, tree.info);

  const tsah::BvhFile file = tsah::loadBvhFile(argv[2]);
  const std::vector<double> costs = tsah::evaluateAnimation(file.bvh, animation, 50);
  double average = 0.0;
  for (double c : costs) average += c / double(costs.size());
  std::printf("%s: %u triangles, %u nodes, %u frames, average cost %.3f\n", argv[2], file.bvh.primCount(),
              file.bvh.nodeCount(), file.bvh.frameCount, average);

  // Refit to the middle of the animation; shoot rays from both sides at the centres of a few triangles.
  tsah::CpuRuntime runtime(tsah::flattenBvh(file.bvh), {animation.indices().begin(), animation.indices().end()},
                           animation.vertexCount());
  const std::vector<float> p = animation.positionsAt(0.5 * (animation.startTime() + animation.endTime()));
  runtime.update(p);
  const tsah::Aabb box = runtime.bounds();
  const float reach = (box.hi.z - box.lo.z) + 1.0f;
  std::vector<tsah::Ray> rays;
  for (uint32_t tri = 0; tri < animation.triangleCount(); tri += animation.triangleCount() / 3 + 1)
    for (float side : {-1.0f, 1.0f}) {
      tsah::Vec3 centre{0.0f, 0.0f, 0.0f};
      for (int c = 0; c < 3; ++c) {
        const uint32_t v = animation.indices()[3 * tri + c];
        centre = centre + tsah::Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]} * (1.0f / 3.0f);
      }
      const tsah::Vec3 dir{0.0f, 0.0f, -side};
      rays.push_back({centre - dir * reach, 0.0f, dir, 1e30f});
    }
  const std::vector<tsah::Hit> hits = tsah::closestHits(runtime, rays);
  for (std::size_t i = 0; i < hits.size(); ++i)
    if (hits[i].valid())
      std::printf("ray %zu: triangle %u at t = %.5f (u %.4f, v %.4f)\n", i, hits[i].tri, hits[i].t, hits[i].u, hits[i].v);
    else
      std::printf("ray %zu: no hit\n", i);
#if defined(CONSUMER_WITH_CUDA)
  if (tsah::cuda::deviceAvailable()) {
    tsah::cuda::GpuRuntime gpu(tsah::flattenBvh(file.bvh), animation);
    gpu.update(p);
    const std::vector<tsah::Hit> gpuHits = gpu.closestHits(rays);
    for (std::size_t i = 0; i < gpuHits.size(); ++i) std::printf("gpu ray %zu: triangle %d\n", i, int(gpuHits[i].tri));
  } else {
    std::printf("no CUDA device: GPU runtime not used\n");
  }
#endif
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "tsah_consumer: %s\n", e.what());
  return 1;
}
