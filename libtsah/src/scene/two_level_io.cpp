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
// its tree) and the flattened TLAS (tlasFlat, the caller's).
TwoLevelFileParts fileParts(const TwoLevelScene& twoLevel, const FlatBvh& tlasFlat) {
  std::vector<const FlatBvh*> trees;
  std::vector<BvhBuildInfo> builds;
  for (const Blas& b : twoLevel.blases) {
    trees.push_back(&b.flat);
    builds.push_back(b.info);
  }
  return twoLevelFileParts(trees, builds, tlasFlat, twoLevel.tlasInfo, instanceBlas(twoLevel.scene),
                           instancePoses(twoLevel), poseRecords(twoLevel), twoLevel.scene.flattenedObjects);
}

}  // namespace

std::vector<uint8_t> encodeTwoLevelScene(const TwoLevelScene& twoLevel) {
  const FlatBvh tlas = flattenBvh(twoLevel.tlas);
  return fileParts(twoLevel, tlas).bytes();
}

void saveTwoLevelScene(const std::string& path, const TwoLevelScene& twoLevel) {
  const FlatBvh tlas = flattenBvh(twoLevel.tlas);
  const TwoLevelFileParts file = fileParts(twoLevel, tlas);
  writeFileAtomically(path, file.parts());
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
  out.objective = file.tlasBuild.objective;
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
  if (file.tlas.frameCount != out.frameTimes.size())
    fail("the TLAS holds boxes for " + std::to_string(file.tlas.frameCount) + " frames, the scene has " +
         std::to_string(out.frameTimes.size()));
  if (file.tlasBuild.topologyHash != instanceTableHash(scene) || file.tlasBuild.timeStart != scene.start ||
      file.tlasBuild.timeEnd != scene.end)
    fail("the TLAS was built for other instances or another time range");
  out.instanceBoxes = instanceBoxesOverFrames(scene, out);
  out.tlas = unflattenBvh(file.tlas);
  out.tlasInfo = file.tlasBuild;
  if (const auto problem = validate(out.tlas, &out.instanceBoxes))
    fail("the TLAS boxes do not hold the scene's instances (" + *problem + ")");
  computeLevelCosts(out);
  out.scene = std::move(scene);
  return out;
}

}  // namespace tsah
