#pragma once
// The animation model: constant triangle connectivity plus keyframed vertex positions.
//
// The topology is stored once for all frames. Vertices that never move (a static environment) are
// stored once, as float32 rest positions; only the moving vertices have one block of
// movingVertexCount*3 floats per keyframe (x0 y0 z0 x1 y1 z1 ... in ascending vertex order). When
// every vertex moves there are no rest positions and the moving vertices are 0..vertexCount-1.
// Positions at any time are the linear interpolation of the two neighbouring keyframes; before the
// first / after the last keyframe they are clamped.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tsah/base/coordinates.hpp"

namespace anim {

struct Bounds {
  std::array<float, 3> min{+3.402823466e38f, +3.402823466e38f, +3.402823466e38f};
  std::array<float, 3> max{-3.402823466e38f, -3.402823466e38f, -3.402823466e38f};

  bool empty() const { return min[0] > max[0]; }
  void extend(const float* p) {
    for (int a = 0; a < 3; ++a) {
      if (p[a] < min[a]) min[a] = p[a];
      if (p[a] > max[a]) max[a] = p[a];
    }
  }
  void extend(const Bounds& b) {
    if (b.empty()) return;
    extend(b.min.data());
    extend(b.max.data());
  }
};

// Where time t falls among keyframe times: positions are (1 - alpha) * keyframe k + alpha * keyframe
// k+1 (alpha == 0 when t is at or outside the ends, which are clamped). The one rule every runtime
// (CPU and GPU) interpolates with, so their positions agree bit for bit.
struct KeyframeBlend {
  uint32_t k = 0;
  float alpha = 0.0f;
};
KeyframeBlend keyframeBlend(std::span<const double> times, double t);

// A keyed camera (e.g. a BART scene's camera path): the default view of `tsah trace` for this input.
struct CameraKey {
  double time = 0.0;
  std::array<float, 3> eye{0, 0, 0};
  std::array<float, 3> lookAt{0, 0, -1};
  std::array<float, 3> up{0, 1, 0};
  float fovyDegrees = 45.0f;
};

// Largest coordinate magnitude accepted anywhere (tsah/base/coordinates.hpp).
using tsah::kMaxCoordinate;
// Smallest extent (the largest side of the bounding box over every keyframe) accepted for a model
// that is not a single point: the surface area of a box of this size is still a normal float
// (1e-36 > 1.2e-38); below it the costs of a tree underflow to zero and the tree is degenerate.
inline constexpr float kMinExtent = 1e-18f;
// The coordinate check (tsah/base/coordinates.hpp), shared with the runtimes' caller buffers.
using tsah::describeBadCoordinate;
using tsah::firstBadCoordinate;

class Animation {
 public:
  Animation() = default;
  // indices: 3 per triangle, each < vertexCount. positions: times.size() blocks of vertexCount*3.
  // times: strictly increasing keyframe times. Throws tsah::FileError (a tsah::DataError) naming
  // the animation when the sizes disagree, an index is out of range, times are not increasing, or a
  // coordinate is NaN/Inf. Vertices that are the same in every keyframe are found here and stored
  // once when that saves memory.
  Animation(std::vector<uint32_t> indices, uint32_t vertexCount, std::vector<float> positions,
            std::vector<double> times, std::string name = {});
  // The split form directly (what a scene bake builds, without ever holding every keyframe whole):
  // rest: vertexCount*3 positions of every vertex (the moving ones' entries are ignored and set to
  // their keyframe 0); moving: ascending ids of the vertices that move; motion: times.size()
  // blocks of moving.size()*3. Same checks as above.
  static Animation withStaticVertices(std::vector<uint32_t> indices, std::vector<float> rest,
                                      std::vector<uint32_t> moving, std::vector<float> motion,
                                      std::vector<double> times, std::string name = {});

  const std::string& name() const { return name_; }
  void setName(std::string name) { name_ = std::move(name); }

  uint32_t vertexCount() const { return vertexCount_; }
  uint32_t triangleCount() const { return static_cast<uint32_t>(indices_.size() / 3); }
  uint32_t keyframeCount() const { return static_cast<uint32_t>(times_.size()); }
  // Triangles whose three vertices span no area in the first keyframe (kept, only counted).
  uint32_t degenerateTriangleCount() const { return degenerate_; }

  std::span<const uint32_t> indices() const { return indices_; }
  std::span<const double> times() const { return times_; }
  // Every vertex of keyframe k (vertexCount*3 floats), assembled from the rest and moving parts.
  std::vector<float> keyframe(uint32_t k) const;
  // Every vertex of every keyframe, keyframe-major (keyframeCount*vertexCount*3 floats).
  std::vector<float> allPositions() const;

  // The static/moving split. movingVertices() is empty when every vertex moves (allMoving()).
  uint32_t movingVertexCount() const { return movingCount_; }
  uint32_t staticVertexCount() const { return vertexCount_ - movingCount_; }
  bool allMoving() const { return movingCount_ == vertexCount_; }
  std::span<const uint32_t> movingVertices() const { return moving_; }
  // vertexCount*3 rest positions (moving vertices hold their keyframe 0); empty when allMoving().
  std::span<const float> restPositions() const { return rest_; }
  // Keyframe k of the moving vertices only: movingVertexCount*3 floats.
  std::span<const float> movingKeyframe(uint32_t k) const;
  // Every keyframe of the moving vertices, keyframe-major (keyframeCount*movingVertexCount*3).
  std::span<const float> motion() const { return motion_; }
  double startTime() const { return times_.empty() ? 0.0 : times_.front(); }
  double endTime() const { return times_.empty() ? 0.0 : times_.back(); }

  // Vertex positions at time t (linear interpolation, clamped to the time range).
  void positionsAt(double t, std::span<float> out) const;
  std::vector<float> positionsAt(double t) const;
  // Writes only the moving vertices' positions at time t into out (vertexCount*3 floats); the
  // static entries are left as they are. A per-frame update that filled out once with positionsAt
  // calls this: its cost is that of the moving vertices only.
  void movingPositionsAt(double t, std::span<float> out) const;

  Bounds keyframeBounds(uint32_t k) const;
  Bounds boundsAt(double t) const;
  // Bounds over every keyframe (and so over every interpolated frame).
  Bounds bounds() const;

  // n times spread uniformly over [startTime, endTime], both ends included (n==1: the start).
  std::vector<double> uniformTimes(uint32_t n) const;
  // A new animation with n keyframes at uniformTimes(n): the paper's representative frames
  // (default 5) or evaluation frames (default 50).
  Animation resample(uint32_t n) const;
  static constexpr uint32_t kMaxResampleFrames = 1000000;  // `tsah resample --frames` and Python's limit
  // The part of the animation between t0 and t1 (clamped), keyframes at t0, t1 and every original
  // keyframe strictly between them.
  Animation segment(double t0, double t1) const;

  // Optional camera path stored with the scene (sorted by time); empty when the input has none.
  std::span<const CameraKey> cameraPath() const { return camera_; }
  void setCameraPath(std::vector<CameraKey> keys) { camera_ = std::move(keys); }

  // Memory held by the positions and topology, in bytes.
  std::size_t memoryBytes() const;
  // What memoryBytes() will be for these counts (before building anything that large).
  static std::size_t memoryBytesFor(uint64_t triangles, uint64_t vertices, uint64_t movingVertices,
                                    uint64_t keyframes);

 private:
  void validate();
  double largestExtent() const;  // the largest side of the box over rest positions and keyframes
  void compactStaticVertices();
  // The moving vertices at time t: contiguous (movingCount*3) when scatter is null, else vertex
  // scatter[m] of a vertexCount*3 buffer. The one copy of the interpolation arithmetic.
  void interpolateMoving(double t, float* out, const uint32_t* scatter) const;
  Bounds staticBounds() const;
  Animation sampledAt(std::vector<double> times) const;

  std::string name_;
  std::vector<uint32_t> indices_;
  uint32_t vertexCount_ = 0;
  uint32_t movingCount_ = 0;
  std::vector<float> rest_;        // vertexCount*3, or empty when every vertex moves
  std::vector<uint32_t> moving_;   // ascending moving vertex ids, or empty when every vertex moves
  std::vector<float> motion_;      // keyframeCount blocks of movingCount*3
  std::vector<double> times_;
  uint32_t degenerate_ = 0;
  std::vector<CameraKey> camera_;
};

}  // namespace anim
