#pragma once
// The named choices at the library boundary, each an enum with one table of names: the command
// line, the Python module, the .tbvh header and the JSON reports read and write them only through
// parse<E>() and name() below, so a name means the same thing everywhere and every unknown name is
// refused the same way.
#include <cstdint>
#include <string>
#include <string_view>

namespace tsah {

// A tree's node layout. The CPU traces bvh2, bvh4 and bvh8 (the value is the width), the GPU bvh2
// and cwbvh (compressed 8-wide); Auto lets the runtime take its fastest.
enum class Layout : uint8_t { Auto = 0, Bvh2 = 2, Bvh4 = 4, Bvh8 = 8, Cwbvh = 9 };

// The single-tree methods of the paper (Section 6.1) and its per-frame lower bound.
enum class Method : uint8_t { Sah0, SahStar, SahRebuild, TSah };

// Which CPU optimizer improves a tree.
enum class OptimizerKind : uint8_t {
  Sequential,  // InsertionOptimizer: the paper's Metropolis-Hastings insertion optimizer, one thread
  Parallel,    // ParallelReinsertionOptimizer: parallel reinsertion on all cores
};

// Node selection of the sequential insertion optimizer.
enum class Selection : uint8_t {
  MetropolisHastings,  // independent chain on Delta_N = sum_i C_i^k S_N(i) (the paper's choice)
  Uniform,             // uniformly random eligible nodes
  BatchSort,           // Bittner 2013: the batch of nodes with the highest inefficiency measure
};

// Where work runs.
enum class Device : uint8_t { Cpu, Cuda };

// The CPU instruction set of the wide layouts' SIMD kernels (the value indexes their tables).
enum class SimdIsa : uint8_t { Sse = 0, Avx2 = 1, Avx512 = 2 };

// How a wide CPU tree holds a frame's triangles (tsah/layout/wide_layout.hpp). Woop: WoopPackets,
// whose rows a refit computes in double precision per triangle. Vertices: one KeyVertexPacket per
// packet, the watertight test on the vertices themselves, and a refit that only gathers them and
// their boxes: the form for trees refitted every frame, such as the poses of a two-level scene (the
// figures of both are in the results log, 2026-11-28).
enum class TriangleForm : uint8_t { Woop, Vertices };

// Names: "auto", "bvh2", "bvh4", "bvh8", "cwbvh"; "sah0", "sahstar", "rebuild", "tsah";
// "sequential", "parallel"; "mh", "random", "batch"; "cpu", "cuda"; "sse", "avx2", "avx512";
// "woop", "vertices".
const char* name(Layout value);
const char* name(Method value);
const char* name(OptimizerKind value);
const char* name(Selection value);
const char* name(Device value);
const char* name(SimdIsa value);
const char* name(TriangleForm value);

// The value named `text`; anything else throws tsah::ConfigError "unknown KIND 'text' (expected
// a, b or c)", KIND being "layout", "method", "optimizer", "node selection", "device",
// "instruction set" or "triangle form".
template <typename E>
E parse(std::string_view text);

// "a, b or c": every name of E, for help texts and messages.
template <typename E>
std::string choices();

// Children per node of a CPU layout (2, 4 or 8); 0 for Auto and Cwbvh.
// The layout the GPU traces for `layout`: Auto is the binary one, which with the fused render
// passes framed all eight data scenes faster than the compressed 8-wide one (docs/cwbvh.md); a
// rule, so that every chunk, GPU and MPI rank of one run traces the same layout.
inline Layout gpuLayout(Layout layout) { return layout == Layout::Auto ? Layout::Bvh2 : layout; }

inline uint32_t layoutWidth(Layout layout) {
  return layout == Layout::Bvh2 || layout == Layout::Bvh4 || layout == Layout::Bvh8 ? uint32_t(layout) : 0u;
}

}  // namespace tsah
