#pragma once
// The tree-building options that `tsah optimize` and `tsah evaluate` share (representative and
// evaluation frames, cost constants, leaf size, which optimizer and how it runs), registered on a
// subcommand in one place; they fill a tsah::TreeOptions (tsah/pipeline.hpp).
#include <cstdint>

#include "tsah/pipeline.hpp"

namespace CLI {
class App;
}

namespace tsah::cli {

// Adds --frames, --eval-frames, --max-leaf, --ct, --ci, --optimizer, --selection, --seed,
// --time-limit, --min-improvement, --threads and --device to a subcommand (with CUDA: the GPU
// optimizer behind --device cuda).
void addTreeOptions(CLI::App& command, TreeOptions& tree, uint32_t& evalFrames);

// --device cuda without the GPU optimizer built or without a device: throws UsageError with one
// line that says which (before any input is read).
void checkTreeDevice(const TreeOptions& tree);

}  // namespace tsah::cli
