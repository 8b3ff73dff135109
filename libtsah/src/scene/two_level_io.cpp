// The two-level structure to and from its .tbvh file (version 3), checked against its scene.
#include <algorithm>

#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"
#include "tsah/io/two_level_file.hpp"
#include "tsah/scene/two_level.hpp"
#include "scene/two_level_parts.hpp"

namespace tsah {

namespace {

TwoLevelPoseRecord recordOf(const Pose& pose) {
  return {pose.blas, pose.time.outside == anim::OutsideRange::Loop ? 1u : 0u, pose.time.offset, pose.time.speed};
}

std::vector<TwoLevelPoseRecord> poseRecords(const TwoLevelScene& twoLevel) {
  std::vector<TwoLevelPoseRecord> records;
  for (const Pose& p : twoLevel.poses) records.push_back(recordOf(p));
  return records;
}

std::vector<uint32_t> instanceBlas(const anim::SceneSources& scene) {
  std::vector<uint32_t> out;
  for (const anim::SceneSourceInstance& i : scene.instances) out.push_back(i.source);
  return out;
}

std::vector<uint32_t> instancePoses(const TwoLevelScene& twoLevel) {
  std::vector<uint32_t> out(twoLevel.instancePose);
  for (uint32_t& p : out)
    if (p == kInvalidIndex) p = kTbvhNoPose;
  return out;
}

// The file's parts over the BLAS's canonical forms the structure keeps (Blas::flat, flattenBvh of
// its tree) and the flattened TLAS trees (tlasFlat, the caller's).
TwoLevelFileParts fileParts(const TwoLevelScene& twoLevel, const std::vector<FlatBvh>& tlasFlat) {
  std::vector<const FlatBvh*> trees, tlases;
  std::vector<BvhBuildInfo> builds, tlasBuilds;
  for (const Blas& b : twoLevel.blases) {
    trees.push_back(&b.flat);
    builds.push_back(b.info);
  }
  for (std::size_t t = 0; t < tlasFlat.size(); ++t) {
    tlases.push_back(&tlasFlat[t]);
    tlasBuilds.push_back(twoLevel.tlases[t].info);
  }
  return twoLevelFileParts(trees, builds, tlases, tlasBuilds, instanceBlas(twoLevel.scene), instancePoses(twoLevel),
                           poseRecords(twoLevel), twoLevel.scene.flattenedObjects);
}

std::vector<FlatBvh> flatTlases(const TwoLevelScene& twoLevel) {
  std::vector<FlatBvh> flat;
  for (const TlasTree& t : twoLevel.tlases) flat.push_back(flattenBvh(t.bvh));
  return flat;
}

}  // namespace

std::vector<uint8_t> encodeTwoLevelScene(const TwoLevelScene& twoLevel) {
  return fileParts(twoLevel, flatTlases(twoLevel)).bytes();
}

void saveTwoLevelScene(const std::string& path, const TwoLevelScene& twoLevel) {
  const std::vector<FlatBvh> tlases = flatTlases(twoLevel);
  writeFileAtomically(path, fileParts(twoLevel, tlases).parts());
}

TwoLevelScene loadTwoLevelSceneFile(const std::string& treePath, anim::SceneSources scene) {
  return decodeTwoLevelScene(readFile(treePath), treePath, std::move(scene));
}

TwoLevelScene decodeTwoLevelScene(std::span<const uint8_t> bytes, const std::string& treePath,
                                  anim::SceneSources scene) {
  TwoLevelFile file = decodeTwoLevelFile(bytes, treePath);
  const std::string& scenePath = scene.description.file;
  const auto fail = [&](const std::string& what) {
    throw DataError(treePath + " was not built for " + scenePath + ": " + what);
  };
  // The objects the file flattened, flattened here the same way before anything is matched.
  const std::size_t objects = scene.description.objects.size();
  for (uint32_t o : file.flattenedObjects)
    if (o >= objects)
      fail("it flattens object " + std::to_string(o) + ", the scene has " + std::to_string(objects) + " objects");
  if (!scene.flattenedObjects.empty() && scene.flattenedObjects != file.flattenedObjects)
    fail("the scene given is flattened otherwise than the file");
  if (scene.flattenedObjects.empty()) scene = anim::flattenObjects(std::move(scene), file.flattenedObjects);
  if (file.blases.size() != scene.sources.size())
    fail("the file holds " + std::to_string(file.blases.size()) + " BLAS, the scene has " +
         std::to_string(scene.sources.size()) + " sources");
  TwoLevelScene out;
  out.objective = file.tlasBuilds.front().objective;
  for (uint32_t s = 0; s < scene.sources.size(); ++s) {
    const anim::Animation& source = *scene.sources[s];
    checkTreeMatchesAnimation(file.blasBuilds[s], treePath, source,
                              scenePath + " (source " + std::to_string(s) + ", " + source.name() + ")");
    Blas blas;
    blas.source = s;
    blas.animated = source.keyframeCount() > 1;
    blas.info = file.blasBuilds[s];
    blas.bvh = unflattenBvh(file.blases[s]);
    blas.flat = std::move(file.blases[s]);
    out.blases.push_back(std::move(blas));
  }
  if (file.instanceBlas != instanceBlas(scene)) fail("its instance table differs from the scene's instances");
  assignPoses(scene, out);
  if (file.instancePose != instancePoses(out) || file.poses != poseRecords(out))
    fail("its poses differ from the scene's (sources and time mappings)");
  out.frameTimes = scene.frameTimes();
  if (file.tlasBuilds.front().timeStart != scene.start || file.tlasBuilds.back().timeEnd != scene.end)
    fail("the TLAS was built for another time range");
  out.instanceBoxes = instanceBoxesOverFrames(scene, out);
  for (std::size_t t = 0; t < file.tlases.size(); ++t) {
    const std::string which = file.tlases.size() == 1 ? std::string("the TLAS") : "TLAS " + std::to_string(t);
    TlasTree tree;
    tree.info = file.tlasBuilds[t];
    tree.range = {tree.info.timeStart, tree.info.timeEnd};
    std::tie(tree.firstFrame, tree.frameCount) = framesInside(out.frameTimes, tree.range);
    if (file.tlases[t].frameCount != tree.frameCount)
      fail(which + " holds boxes for " + std::to_string(file.tlases[t].frameCount) + " frames, the scene has " +
           std::to_string(tree.frameCount) + " in its time range");
    if (tree.info.topologyHash != instanceTableHash(scene)) fail(which + " was built for other instances");
    tree.bvh = unflattenBvh(file.tlases[t]);
    const PrimitiveBoxes boxes = frameSlice(out.instanceBoxes, tree.firstFrame, tree.frameCount);
    if (const auto problem = validate(tree.bvh, &boxes))
      fail(which + " boxes do not hold the scene's instances (" + *problem + ")");
    out.tlases.push_back(std::move(tree));
  }
  computeLevelCosts(out);
  out.scene = std::move(scene);
  return out;
}

}  // namespace tsah
