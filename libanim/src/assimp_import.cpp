// glTF 2.0 / FBX / Collada (and anything else Assimp reads) baked into vertex keyframes.
//
// Assimp gives a node hierarchy with rest transforms, meshes attached to nodes (with bones: offset
// matrices = inverse bind matrices, and morph targets stored as complete target shapes), and clips of
// node channels (translation, rotation, scale keys) and morph-weight channels. Per keyframe we
// evaluate the chosen clip at that time, compose the global node transforms, blend the morph targets,
// skin (sum of weight * global(bone) * offset(bone) * vertex, the mesh's own node transform ignored as
// glTF specifies) or place unskinned meshes with their node's global transform, and write the merged
// world-space positions.
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <unordered_map>

#include "anim/assimp_import.hpp"
#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"

namespace anim {

namespace {

constexpr uint64_t kMaxPositionBytes = uint64_t(8) << 30;
constexpr std::size_t kMaxFrames = 1'000'000;
constexpr uint64_t kMaxVertices = uint64_t(1) << 31;
constexpr double kDefaultTicksPerSecond = 25.0;  // Assimp's convention when a file gives none

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

using V3 = std::array<double, 3>;
struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};
// Row-major 3x4 affine transform (last column: translation).
using Affine = std::array<double, 12>;

Affine multiply(const Affine& a, const Affine& b) {
  Affine r;
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 4; ++col)
      r[4 * row + col] = a[4 * row] * b[col] + a[4 * row + 1] * b[4 + col] + a[4 * row + 2] * b[8 + col] +
                         (col == 3 ? a[4 * row + 3] : 0.0);
  return r;
}

Affine fromAssimp(const aiMatrix4x4& m) {
  return {m.a1, m.a2, m.a3, m.a4, m.b1, m.b2, m.b3, m.b4, m.c1, m.c2, m.c3, m.c4};
}

V3 transformPoint(const Affine& m, const V3& p) {
  return {m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3], m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
          m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]};
}

Quat normalized(const Quat& q) {
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  return n > 0.0 ? Quat{q.w / n, q.x / n, q.y / n, q.z / n} : Quat{};
}

// Shortest-arc spherical interpolation (what glTF and Assimp's own evaluator do).
Quat slerp(Quat a, Quat b, double t) {
  double c = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
  if (c < 0.0) {
    b = {-b.w, -b.x, -b.y, -b.z};
    c = -c;
  }
  double k0 = 1.0 - t, k1 = t;
  if (c < 0.9999) {
    const double angle = std::acos(std::min(c, 1.0)), s = std::sin(angle);
    k0 = std::sin((1.0 - t) * angle) / s;
    k1 = std::sin(t * angle) / s;
  }
  return normalized({k0 * a.w + k1 * b.w, k0 * a.x + k1 * b.x, k0 * a.y + k1 * b.y, k0 * a.z + k1 * b.z});
}

Affine compose(const V3& t, const Quat& qIn, const V3& s) {
  const Quat q = normalized(qIn);
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z, xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z,
               wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  const double r[9] = {1 - 2 * (yy + zz), 2 * (xy - wz),     2 * (xz + wy),  //
                       2 * (xy + wz),     1 - 2 * (xx + zz), 2 * (yz - wx),  //
                       2 * (xz - wy),     2 * (yz + wx),     1 - 2 * (xx + yy)};
  Affine m;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) m[4 * row + col] = r[3 * row + col] * s[col];
    m[4 * row + 3] = t[row];
  }
  return m;
}

// Index of the last key at or before `tick` and the blend weight towards the next one (clamped).
template <typename Key>
std::pair<unsigned, double> bracket(const Key* keys, unsigned n, double tick) {
  if (n == 1 || tick <= keys[0].mTime) return {0, 0.0};
  if (tick >= keys[n - 1].mTime) return {n - 1, 0.0};
  const Key* it = std::upper_bound(keys, keys + n, tick, [](double t, const Key& k) { return t < k.mTime; });
  const unsigned i = unsigned(it - keys) - 1;
  const double span = keys[i + 1].mTime - keys[i].mTime;
  return {i, span > 0.0 ? (tick - keys[i].mTime) / span : 0.0};
}

V3 toV3(const aiVector3D& v) { return {v.x, v.y, v.z}; }

V3 sampleVector(const aiVectorKey* keys, unsigned n, double tick, const V3& fallback) {
  if (n == 0) return fallback;
  const auto [i, a] = bracket(keys, n, tick);
  const V3 p = toV3(keys[i].mValue);
  if (a == 0.0) return p;
  const V3 q = toV3(keys[i + 1].mValue);
  return {p[0] + a * (q[0] - p[0]), p[1] + a * (q[1] - p[1]), p[2] + a * (q[2] - p[2])};
}

Quat sampleRotation(const aiQuatKey* keys, unsigned n, double tick, const Quat& fallback) {
  if (n == 0) return fallback;
  const auto [i, a] = bracket(keys, n, tick);
  const aiQuaternion& p = keys[i].mValue;
  if (a == 0.0) return normalized({p.w, p.x, p.y, p.z});
  const aiQuaternion& q = keys[i + 1].mValue;
  return slerp({p.w, p.x, p.y, p.z}, {q.w, q.x, q.y, q.z}, a);
}

struct SceneNode {
  const aiNode* node = nullptr;
  int parent = -1;
  const aiNodeAnim* channel = nullptr;
  V3 restT{0, 0, 0}, restS{1, 1, 1};
  Quat restR;
};

// One placement of a mesh (a mesh referenced by several nodes is placed once per node).
struct MeshInstance {
  int node;
  const aiMesh* mesh;
  uint32_t firstVertex;
  const aiMeshMorphAnim* morph = nullptr;
  std::vector<int> boneNodes;  // scene node of each bone
};

std::string clipLabel(const aiAnimation* a, unsigned i) {
  if (a->mName.length) return a->mName.C_Str();
  std::string label = "#";  // (not "#" + to_string: GCC 12 warns falsely about that)
  label += std::to_string(i);
  return label;
}

const aiAnimation* chooseClip(const aiScene* scene, const std::string& clip, const std::string& file) {
  if (scene->mNumAnimations == 0) {
    if (!clip.empty()) throw tsah::FileError(file, "has no animation clips, so clip '" + clip + "' cannot be chosen");
    return nullptr;
  }
  if (clip.empty()) return scene->mAnimations[0];
  for (unsigned i = 0; i < scene->mNumAnimations; ++i)
    if (clip == scene->mAnimations[i]->mName.C_Str()) return scene->mAnimations[i];
  if (!clip.empty() && clip.size() < 10 && std::all_of(clip.begin(), clip.end(), [](unsigned char c) { return std::isdigit(c); })) {
    const unsigned long i = std::stoul(clip);
    if (i < scene->mNumAnimations) return scene->mAnimations[i];
  }
  std::string list;
  for (unsigned i = 0; i < scene->mNumAnimations; ++i) list += (i ? ", " : "") + clipLabel(scene->mAnimations[i], i);
  throw tsah::FileError(file, "no clip '" + clip + "' (clips: " + list + ")");
}

// Keyframe times in seconds: every 1/fps over the clip, or (fps 0) every distinct key time of it.
std::vector<double> frameTimes(const aiAnimation* clip, double fps, double ticksPerSecond, const std::string& file) {
  if (!clip) return {0.0};
  std::vector<double> ticks;
  auto addKeys = [&](const auto* keys, unsigned n) {
    for (unsigned k = 0; k < n; ++k) {
      if (!std::isfinite(keys[k].mTime)) throw tsah::FileError(file, "clip has a non-finite key time");
      ticks.push_back(keys[k].mTime);
    }
  };
  for (unsigned c = 0; c < clip->mNumChannels; ++c) {
    const aiNodeAnim* ch = clip->mChannels[c];
    addKeys(ch->mPositionKeys, ch->mNumPositionKeys);
    addKeys(ch->mRotationKeys, ch->mNumRotationKeys);
    addKeys(ch->mScalingKeys, ch->mNumScalingKeys);
  }
  for (unsigned c = 0; c < clip->mNumMorphMeshChannels; ++c) addKeys(clip->mMorphMeshChannels[c]->mKeys, clip->mMorphMeshChannels[c]->mNumKeys);
  std::sort(ticks.begin(), ticks.end());
  if (fps > 0.0) {
    double end = std::isfinite(clip->mDuration) ? clip->mDuration : 0.0;
    if (!ticks.empty()) end = std::max(end, ticks.back());
    const double count = std::floor(end / ticksPerSecond * fps + 1e-9) + 1.0;
    if (!(count <= double(kMaxFrames))) throw tsah::FileError(file, "the clip is too long to sample at " + std::to_string(fps) + " fps");
    std::vector<double> times(static_cast<std::size_t>(std::max(1.0, count)));
    for (std::size_t i = 0; i < times.size(); ++i) times[i] = double(i) / fps;
    return times;
  }
  std::vector<double> times;
  for (double t : ticks) {
    const double s = t / ticksPerSecond;
    if (times.empty() || s > times.back() + 1e-9 * std::max(1.0, std::fabs(s))) times.push_back(s);
  }
  if (times.size() > kMaxFrames) throw tsah::FileError(file, "the clip has more than " + std::to_string(kMaxFrames) + " key times");
  if (times.empty()) times.push_back(0.0);
  return times;
}

// Merges vertices whose positions agree in every keyframe (Assimp splits vertices at UV and normal
// seams; the geometry only needs one).
void weldVertices(std::vector<uint32_t>& indices, std::vector<float>& positions, uint32_t& vertexCount, std::size_t frames) {
  const std::size_t n = vertexCount, perFrame = std::size_t(vertexCount) * 3;
  auto coordinate = [&](std::size_t v, std::size_t f, int a) { return positions[f * perFrame + 3 * v + a]; };
  std::vector<std::pair<uint64_t, uint32_t>> hashes(n);
  for (std::size_t v = 0; v < n; ++v) {
    uint64_t h = 1469598103934665603ull;
    for (std::size_t f = 0; f < frames; ++f)
      for (int a = 0; a < 3; ++a) {
        const float x = coordinate(v, f, a) + 0.0f;  // +0.0f folds -0 into 0
        uint32_t bits;
        std::memcpy(&bits, &x, 4);
        h = (h ^ bits) * 1099511628211ull;
      }
    hashes[v] = {h, uint32_t(v)};
  }
  std::sort(hashes.begin(), hashes.end());
  std::vector<uint32_t> representative(n);
  for (std::size_t v = 0; v < n; ++v) representative[v] = uint32_t(v);
  auto same = [&](std::size_t a, std::size_t b) {
    for (std::size_t f = 0; f < frames; ++f)
      for (int k = 0; k < 3; ++k)
        if (coordinate(a, f, k) != coordinate(b, f, k)) return false;
    return true;
  };
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i;
    while (j < n && hashes[j].first == hashes[i].first) ++j;
    for (std::size_t a = i; a < j; ++a) {
      const uint32_t va = hashes[a].second;
      if (representative[va] != va) continue;
      for (std::size_t b = a + 1; b < j; ++b) {
        const uint32_t vb = hashes[b].second;
        if (representative[vb] == vb && same(va, vb)) representative[vb] = va;
      }
    }
    i = j;
  }
  // Renumber the kept vertices in their original order.
  std::vector<uint32_t> newIndex(n, 0);
  uint32_t kept = 0;
  for (std::size_t v = 0; v < n; ++v)
    if (representative[v] == v) newIndex[v] = kept++;
  if (kept == n) return;
  std::vector<float> compact(std::size_t(kept) * 3 * frames);
  for (std::size_t f = 0; f < frames; ++f)
    for (std::size_t v = 0; v < n; ++v)
      if (representative[v] == v)
        std::memcpy(&compact[f * kept * 3 + 3 * newIndex[v]], &positions[f * perFrame + 3 * v], 3 * sizeof(float));
  for (uint32_t& i : indices) i = newIndex[representative[i]];
  positions = std::move(compact);
  vertexCount = kept;
}

Animation bake(const aiScene* scene, const std::string& file, const LoadOptions& options) {
  if (!(options.fps >= 0.0) || !std::isfinite(options.fps))
    throw tsah::FileError(file, "frame rate must be a finite number >= 0");
  if (!scene->mRootNode) throw tsah::FileError(file, "the scene has no node hierarchy");
  const aiAnimation* clip = chooseClip(scene, options.clip, file);
  const double tps = clip && clip->mTicksPerSecond > 0.0 && std::isfinite(clip->mTicksPerSecond) ? clip->mTicksPerSecond
                                                                                                  : kDefaultTicksPerSecond;
  std::vector<std::string> warnings;

  // The node hierarchy, parents first, with each node's channel in the clip.
  std::vector<SceneNode> nodes;
  std::unordered_map<std::string, int> byName;
  {
    std::vector<std::pair<const aiNode*, int>> stack{{scene->mRootNode, -1}};
    while (!stack.empty()) {
      auto [n, parent] = stack.back();
      stack.pop_back();
      if (nodes.size() > (std::size_t(1) << 24)) throw tsah::FileError(file, "the node hierarchy is too large");
      SceneNode sn;
      sn.node = n;
      sn.parent = parent;
      aiVector3D s, t;
      aiQuaternion r;
      n->mTransformation.Decompose(s, r, t);
      sn.restT = toV3(t);
      sn.restS = toV3(s);
      sn.restR = {r.w, r.x, r.y, r.z};
      const int index = int(nodes.size());
      byName.emplace(n->mName.C_Str(), index);
      nodes.push_back(sn);
      for (unsigned c = n->mNumChildren; c-- > 0;) stack.push_back({n->mChildren[c], index});
    }
  }
  if (clip)
    for (unsigned c = 0; c < clip->mNumChannels; ++c) {
      const auto it = byName.find(clip->mChannels[c]->mNodeName.C_Str());
      if (it != byName.end()) nodes[it->second].channel = clip->mChannels[c];
    }

  // Mesh placements and the merged topology.
  std::vector<MeshInstance> instances;
  std::vector<uint32_t> indices;
  uint64_t vertexCount = 0, skippedFaces = 0;
  for (int i = 0; i < int(nodes.size()); ++i) {
    const aiNode* n = nodes[i].node;
    for (unsigned k = 0; k < n->mNumMeshes; ++k) {
      if (n->mMeshes[k] >= scene->mNumMeshes) throw tsah::FileError(file, "a node references a missing mesh");
      const aiMesh* mesh = scene->mMeshes[n->mMeshes[k]];
      MeshInstance inst{i, mesh, uint32_t(vertexCount), nullptr, {}};
      uint64_t triangles = 0;
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices != 3) {
          ++skippedFaces;
          continue;
        }
        for (int c = 0; c < 3; ++c) {
          if (face.mIndices[c] >= mesh->mNumVertices) throw tsah::FileError(file, "a face references a missing vertex");
          indices.push_back(uint32_t(vertexCount + face.mIndices[c]));
        }
        ++triangles;
      }
      if (triangles == 0) continue;
      for (unsigned b = 0; b < mesh->mNumBones; ++b) {
        const aiBone* bone = mesh->mBones[b];
        const auto it = byName.find(bone->mName.C_Str());
        if (it == byName.end()) throw tsah::FileError(file, "bone '" + std::string(bone->mName.C_Str()) + "' has no node");
        for (unsigned w = 0; w < bone->mNumWeights; ++w)
          if (bone->mWeights[w].mVertexId >= mesh->mNumVertices) throw tsah::FileError(file, "a bone weight references a missing vertex");
        inst.boneNodes.push_back(it->second);
      }
      if (clip)
        for (unsigned c = 0; c < clip->mNumMorphMeshChannels; ++c) {
          const aiMeshMorphAnim* ch = clip->mMorphMeshChannels[c];
          if (ch->mName == n->mName || ch->mName == mesh->mName) inst.morph = ch;
        }
      for (unsigned a = 0; a < mesh->mNumAnimMeshes; ++a)
        if (!mesh->mAnimMeshes[a]->mVertices || mesh->mAnimMeshes[a]->mNumVertices != mesh->mNumVertices)
          throw tsah::FileError(file, "a morph target of mesh '" + std::string(mesh->mName.C_Str()) + "' has no or too few positions");
      instances.push_back(std::move(inst));
      vertexCount += mesh->mNumVertices;
      if (vertexCount > kMaxVertices) throw tsah::FileError(file, "the scene has more than " + std::to_string(kMaxVertices) + " vertices");
    }
  }
  if (indices.empty()) throw tsah::FileError(file, "the scene holds no triangles");
  if (skippedFaces) warnings.push_back(file + ": skipped " + std::to_string(skippedFaces) + " point and line primitives");
  if (scene->mNumAnimations > 1) {
    unsigned chosen = 0;
    while (scene->mAnimations[chosen] != clip) ++chosen;
    warnings.push_back(file + ": baked clip '" + clipLabel(clip, chosen) + "' of " +
                       std::to_string(scene->mNumAnimations) + " (choose another with the clip option)");
  }

  const std::vector<double> times = frameTimes(clip, options.fps, tps, file);
  const std::size_t perFrame = std::size_t(vertexCount) * 3;
  if ((long double)perFrame * sizeof(float) * times.size() > (long double)kMaxPositionBytes)
    throw tsah::FileError(file, std::to_string(times.size()) + " frames x " + std::to_string(vertexCount) +
                                " vertices need more than " + std::to_string(kMaxPositionBytes >> 30) +
                                " GiB of keyframe positions; sample fewer frames");
  std::vector<float> positions(perFrame * times.size());
  std::vector<Affine> global(nodes.size());
  std::vector<V3> morphed, skinned;
  std::vector<double> skinWeight;
  for (std::size_t f = 0; f < times.size(); ++f) {
    const double tick = times[f] * tps;
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      const SceneNode& sn = nodes[i];
      Affine local;
      if (sn.channel) {
        const aiNodeAnim* ch = sn.channel;
        local = compose(sampleVector(ch->mPositionKeys, ch->mNumPositionKeys, tick, sn.restT),
                        sampleRotation(ch->mRotationKeys, ch->mNumRotationKeys, tick, sn.restR),
                        sampleVector(ch->mScalingKeys, ch->mNumScalingKeys, tick, sn.restS));
      } else {
        local = fromAssimp(sn.node->mTransformation);
      }
      global[i] = sn.parent < 0 ? local : multiply(global[sn.parent], local);
    }
    float* out = positions.data() + f * perFrame;
    for (const MeshInstance& inst : instances) {
      const aiMesh* mesh = inst.mesh;
      const unsigned nv = mesh->mNumVertices;
      morphed.resize(nv);
      for (unsigned v = 0; v < nv; ++v) morphed[v] = toV3(mesh->mVertices[v]);
      if (mesh->mNumAnimMeshes > 0) {
        // Target weights: the clip's morph channel at this time, else the targets' default weights.
        std::vector<double> weights(mesh->mNumAnimMeshes, 0.0);
        if (inst.morph && inst.morph->mNumKeys > 0) {
          const auto [k, a] = bracket(inst.morph->mKeys, inst.morph->mNumKeys, tick);
          auto addKey = [&](const aiMeshMorphKey& key, double share) {
            for (unsigned j = 0; j < key.mNumValuesAndWeights; ++j)
              if (key.mValues[j] < weights.size()) weights[key.mValues[j]] += share * key.mWeights[j];
          };
          addKey(inst.morph->mKeys[k], 1.0 - a);
          if (a > 0.0) addKey(inst.morph->mKeys[k + 1], a);
        } else {
          for (unsigned j = 0; j < mesh->mNumAnimMeshes; ++j) weights[j] = mesh->mAnimMeshes[j]->mWeight;
        }
        // Assimp stores complete target shapes: base + w (target - base), except for relative
        // (delta) targets of Collada's RELATIVE method.
        const bool deltas = mesh->mMethod == aiMorphingMethod_MORPH_RELATIVE;
        for (unsigned j = 0; j < mesh->mNumAnimMeshes; ++j) {
          if (weights[j] == 0.0) continue;
          const aiVector3D* target = mesh->mAnimMeshes[j]->mVertices;
          for (unsigned v = 0; v < nv; ++v) {
            const V3 base = toV3(mesh->mVertices[v]);
            for (int c = 0; c < 3; ++c) morphed[v][c] += weights[j] * (target[v][c] - (deltas ? 0.0 : base[c]));
          }
        }
      }
      float* dst = out + 3 * std::size_t(inst.firstVertex);
      if (mesh->mNumBones == 0) {
        const Affine& m = global[inst.node];
        for (unsigned v = 0; v < nv; ++v) {
          const V3 p = transformPoint(m, morphed[v]);
          for (int c = 0; c < 3; ++c) dst[3 * v + c] = float(p[c]);
        }
        continue;
      }
      skinned.assign(nv, V3{0, 0, 0});
      skinWeight.assign(nv, 0.0);
      for (unsigned b = 0; b < mesh->mNumBones; ++b) {
        const aiBone* bone = mesh->mBones[b];
        const Affine m = multiply(global[inst.boneNodes[b]], fromAssimp(bone->mOffsetMatrix));
        for (unsigned w = 0; w < bone->mNumWeights; ++w) {
          const unsigned v = bone->mWeights[w].mVertexId;
          const double weight = bone->mWeights[w].mWeight;
          if (!(weight != 0.0)) continue;
          const V3 p = transformPoint(m, morphed[v]);
          for (int c = 0; c < 3; ++c) skinned[v][c] += weight * p[c];
          skinWeight[v] += weight;
        }
      }
      const Affine& meshNode = global[inst.node];
      for (unsigned v = 0; v < nv; ++v) {
        // Weights are normalised; a vertex no bone holds stays with its mesh's node.
        const V3 p = skinWeight[v] > 1e-12 ? V3{skinned[v][0] / skinWeight[v], skinned[v][1] / skinWeight[v],
                                                skinned[v][2] / skinWeight[v]}
                                           : transformPoint(meshNode, morphed[v]);
        for (int c = 0; c < 3; ++c) dst[3 * v + c] = float(p[c]);
      }
    }
    if (options.progress) options.progress(f + 1, times.size());
  }

  uint32_t vertices = uint32_t(vertexCount);
  weldVertices(indices, positions, vertices, times.size());
  if (options.warning)
    for (const auto& w : warnings) options.warning(w);
  return Animation(std::move(indices), vertices, std::move(positions), times,
                   std::filesystem::path(file).stem().string());
}

const aiScene* readScene(Assimp::Importer& importer, const std::string& path) {
  tsah::checkInputFile(path);  // a FIFO or device would block or never end inside Assimp
  const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate | aiProcess_ValidateDataStructure);
  if (!scene) throw tsah::FileError(path, std::string("cannot import: ") + importer.GetErrorString());
  if (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) throw tsah::FileError(path, "the file holds an incomplete scene");
  return scene;
}

}  // namespace

bool isModelFile(const std::string& path) {
  const std::string ext = lowerExtension(path);
  return ext == ".md2" || ext == ".gltf" || ext == ".glb" || ext == ".fbx" || ext == ".dae";
}

Animation importModel(const std::string& path, const LoadOptions& options) {
  if (lowerExtension(path) == ".md2") {
    const std::vector<uint8_t> bytes = tsah::readFile(path, std::size_t(1) << 30);
    return decodeMd2(bytes, path, options);
  }
  Assimp::Importer importer;
  return bake(readScene(importer, path), path, options);
}

std::vector<std::string> modelClips(const std::string& path) {
  if (lowerExtension(path) == ".md2") {
    const std::vector<uint8_t> bytes = tsah::readFile(path, std::size_t(1) << 30);
    return md2Clips(bytes, path);
  }
  Assimp::Importer importer;
  const aiScene* scene = readScene(importer, path);
  std::vector<std::string> clips;
  for (unsigned i = 0; i < scene->mNumAnimations; ++i) clips.push_back(clipLabel(scene->mAnimations[i], i));
  return clips;
}

}  // namespace anim
