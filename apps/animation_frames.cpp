#include "animation_frames.hpp"

#include <stdexcept>

namespace tsah::cli {

FrameSource animationFrames(const anim::Animation& animation, std::vector<double> times) {
  FrameSource source;
  source.frameCount = static_cast<uint32_t>(times.size());
  source.primCount = animation.triangleCount();
  source.fill = [&animation, times = std::move(times)](uint32_t frame, std::span<Aabb> out) {
    const std::vector<float> positions = animation.positionsAt(times[frame]);
    triangleBoxes(animation.indices(), positions, out);
  };
  return source;
}

PrimitiveBoxes representativeBoxes(const anim::Animation& animation, uint32_t frames) {
  const anim::Animation rep = animation.resample(frames);
  return triangleBoxes(rep.indices(), rep.allPositions(), frames);
}

InsertionOptimizer::Selection parseSelection(const std::string& name) {
  using Selection = InsertionOptimizer::Selection;
  if (name == "mh") return Selection::MetropolisHastings;
  if (name == "random") return Selection::Uniform;
  if (name == "batch") return Selection::BatchSort;
  throw std::invalid_argument("unknown node selection '" + name + "' (expected mh, random or batch)");
}

}  // namespace tsah::cli
