#pragma once
// Procedural animations for samples and tests, deterministic for a given seed.
#include <cstdint>
#include <string>
#include <string_view>

#include "anim/animation.hpp"

namespace anim {

enum class GeneratorKind {
  Explode,  // a sphere broken into fragments that fly apart and tumble (the paper's Dragon-Bunny case)
  Wave,     // a cloth-like sheet deformed by travelling waves
  Swap,     // two groups of objects that pass through each other, so spatial grouping changes
};

struct GeneratorOptions {
  uint32_t triangles = 4000;  // approximate target; the generator rounds to its own tessellation
  uint32_t frames = 30;       // keyframes, at times 0..frames-1
  uint64_t seed = 1;
};

Animation generate(GeneratorKind kind, const GeneratorOptions& options);
// "explode", "wave", "swap"; throws tsah::ConfigError for anything else.
GeneratorKind parseGeneratorKind(std::string_view name);
const char* generatorName(GeneratorKind kind);

}  // namespace anim
