#pragma once
// The GPU two-level runtime's motion blur (docs/motion-blur.md, "Two-level scenes"), the device
// counterpart of tsah::TwoLevelRuntime::updateShutter and its traces at each ray's time: per key of
// a shutter the instances' float world matrices, every moving pose's BLAS interpolated and refitted
// at each key on the device (one batch per source) and turned into the flat blurred runtime's
// layout (blurred_trace.hpp), the instances' key boxes (tsah::instanceKeyBox, on the host, over the
// union of their BLAS's key root boxes) and the TLAS refitted at every key. A ray traverses the TLAS
// with its nodes lerped at its time (lerpNode), tests a slot's instance box lerped (lerpBox), moves
// into instance space by the lerped and inverted map of a moving instance (instanceSpaceOfRows, the
// CPU's code) or the instant one of a still instance, and traces a moving pose's blurred BLAS at its
// time (the flat blurred frame's loop) or the instance's instant BLAS. No CUDA syntax here.
#include <cuda_runtime_api.h>

#include <cstdint>
#include <span>
#include <vector>

#include "blurred_trace.hpp"
#include "event_timer.hpp"
#include "tsah/core/instance_transform.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "two_level_kernels.hpp"
#include "two_level_query.hpp"

namespace tsah::cuda::detail {

// A BLAS source as the GPU two-level runtime uploaded it: what a pose's keys are interpolated and
// refitted from.
struct BlurSource {
  const FlatBvh* topology = nullptr;
  const float* keyframes = nullptr;
  const uint32_t* movingIds = nullptr;  // null: every vertex moves
  uint32_t movingCount = 0;
  const uint32_t* nodeParent = nullptr;
  const LeafRecord* leaves = nullptr;
  uint32_t leafCount = 0;
  const uint32_t* slotVertices = nullptr;
  const uint32_t* triIndex = nullptr;
};

// What a blurred frame is built from: the runtime's sources (per BLAS), the T-SAH TLAS's refit data,
// and its instant state at the shutter's close (each instance's world -> instance map, visibility and
// BLAS view, which still instances and still poses trace), all on `stream`.
struct TwoLevelBlurAccess {
  const TwoLevelScene* scene = nullptr;
  cudaStream_t stream = nullptr;
  std::vector<BlurSource> sources;
  const FlatBvh* tlas = nullptr;
  const uint32_t* tlasParent = nullptr;
  const LeafRecord* tlasLeaves = nullptr;
  uint32_t tlasLeafCount = 0;
  const uint32_t* tlasTriIndex = nullptr;
  const InstanceState* instances = nullptr;
  const BlasView* views = nullptr;
  bool compressedBlas = false;  // the views in the compressed layout (TlasScene::compressedBlas)
};

// Per instance of a blurred frame: whether its float matrix differs between keys (it is lerped and
// inverted per ray), and its pose's blurred BLAS (an index into BlurredTlasScene::layouts), or
// kInvalidIndex when it traces its instant BLAS view (a static source or a still pose).
struct BlurredInstance {
  uint32_t moving = 0;
  uint32_t layout = kInvalidIndex;
};

// A moving pose's vertex positions at the keys (keyCount blocks of keyStride floats, xyz per
// vertex): what a blurred frame's rendered surfaces lerp at the ray's time.
struct BlurredPosePositions {
  const float* keys = nullptr;
  uint64_t keyStride = 0;
};

// A blurred frame as the trace reads it; key k's arrays start at k times their count.
struct BlurredTlasScene {
  const GpuBvhNode* keyNodes = nullptr;  // the TLAS's interior nodes refitted at each key
  uint32_t nodeCount = 0;
  const Aabb* keyRootBoxes = nullptr;    // the TLAS's root box at each key
  const float* keyTimes = nullptr;       // shutter fractions (first 0, last 1)
  uint32_t keyCount = 0;
  int32_t rootRef = 0;
  uint32_t rootCount = 0;
  const uint32_t* triIndex = nullptr;    // TLAS slot -> instance
  uint32_t instanceCount = 0;
  const Aabb* keyBoxes = nullptr;        // instanceKeyBox of each instance at each key
  const Affine3x4* keyToWorld = nullptr; // each instance's float world matrix at each key
  const BlurredInstance* blurred = nullptr;
  const InstanceState* instances = nullptr;  // the instant state at the close
  const BlasView* views = nullptr;
  bool compressedBlas = false;               // the views in the compressed layout (TlasScene::compressedBlas)
  const BlurredLayout* layouts = nullptr;    // the moving poses' blurred BLAS
  const BlurredPosePositions* posePositions = nullptr;  // per layout: its pose's key positions
};

// Per instance, the box its instant BLAS view's root holds (the union over the keys of a still BLAS).
void launchInstanceRootBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                             cudaStream_t stream);
// One thread per ray at shutter fraction times[i]: closest hits into hits, or (occluded non-null)
// any hits into occluded.
void launchBlurredTwoLevelTrace(const BlurredTlasScene& scene, const Ray* rays, const float* times, uint32_t count,
                                InstanceHit* hits, uint8_t* occluded, cudaStream_t stream);
// The same for rays, times and results in the caller's arrays.
void launchBlurredTwoLevelArrayTrace(const BlurredTlasScene& scene, const ArrayRays& rays, const ArrayTimes& times,
                                     const ArrayInstanceHits& hits, uint8_t* occluded, cudaStream_t stream);

// The blurred frame's device state, rebuilt by each build() (buffers grow, never shrink).
class TwoLevelBlur {
 public:
  TwoLevelBlur();
  // Builds the blurred frame of keys (scene times, at least 2) from `motion` (shutterMotion of the
  // same keys, something moving); the instant state in `access` must be the close's. Synchronizes.
  void build(const TwoLevelBlurAccess& access, std::span<const double> keys, const ShutterMotion& motion);
  void end() { keyTimes_.clear(); }  // the frame is instant again
  bool blurred() const { return !keyTimes_.empty(); }
  const BlurredTlasScene& scene() const { return scene_; }  // the frame's device state (the renderer's)
  std::span<const float> keyTimes() const { return keyTimes_; }
  // Instance boxes at key k (host copy; what the TLAS at key k was refitted from).
  std::span<const Aabb> keyInstanceBoxes(std::size_t key) const;
  // The rays at their times (shutter fractions) on the stream the frame was built on.
  template <bool AnyHit, typename Result>
  std::vector<Result> trace(std::span<const Ray> rays, std::span<const float> times, RayPassStats* stats);

 private:
  // A source's moving poses, each refitted at every key in one batch (item j * keys + k: pose j at
  // key k), and their blurred layouts.
  struct PoseKeys {
    DeviceBuffer<float> startPositions;    // the source at its start time (static vertices at rest)
    DeviceBuffer<GpuBvhNode> startNodes;   // the topology's nodes (child references)
    DeviceBuffer<float> positions;
    DeviceBuffer<GpuBvhNode> nodes;
    DeviceBuffer<uint32_t> counters;
    DeviceBuffer<RootInfo> roots;
    DeviceBuffer<FrameParams> frames;
    DeviceBuffer<Aabb> keyRootBoxes;
    DeviceBuffer<motion::BlurredNodeSegment> layoutNodes;
    DeviceBuffer<KeyTriangle> layoutTriangles;
  };
  // The moving poses' keys and layouts: layouts (and positions) get one per moving pose,
  // poseLayout[p] its index (kInvalidIndex for the others), poseUnion[p] the union of its key root
  // boxes. Waits for them.
  void buildPoses(const TwoLevelBlurAccess& access, const ShutterMotion& motion, std::size_t keyCount,
                  std::vector<BlurredLayout>& layouts, std::vector<BlurredPosePositions>& positions,
                  std::vector<uint32_t>& poseLayout, std::vector<Aabb>& poseUnion);

  EventTimer events_;
  cudaStream_t stream_ = nullptr;
  std::vector<float> keyTimes_;
  std::vector<Aabb> hostKeyBoxes_;
  std::vector<PoseKeys> poseKeys_;  // per source (empty for a static one)
  DeviceBuffer<float> deviceKeyTimes_;
  DeviceBuffer<BlurredLayout> layouts_;
  DeviceBuffer<BlurredPosePositions> posePositions_;
  DeviceBuffer<BlurredInstance> instances_;
  DeviceBuffer<Aabb> keyBoxes_, rootBoxes_, tlasKeyRootBoxes_;
  DeviceBuffer<Affine3x4> keyToWorld_;
  DeviceBuffer<GpuBvhNode> tlasKeyNodes_;
  DeviceBuffer<uint32_t> tlasCounters_;
  DeviceBuffer<RootInfo> tlasKeyRoots_;
  BlurredTlasScene scene_;
  TwoLevelQuery query_;
  DeviceBuffer<float> rayTimes_;
};

}  // namespace tsah::cuda::detail
