#pragma once
// A tree's boxes as a mesh that any viewer opens: selected by depth range, share of the frame's cost
// and growth over the animation, coloured in bands by depth or by growth over the animation, drawn as thin bars along every
// box edge (triangles: every viewer shows them) or as line segments (OBJ `l`, PLY `edge`).
// Written as binary PLY with vertex colours or as OBJ with one material per colour band.
#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/inspect/tree_quality.hpp"

namespace tsah {

inline constexpr uint32_t kBoxViewBands = 8;               // colour bands of the boxes
inline constexpr uint32_t kBoxViewMeshBand = kBoxViewBands;  // the optional scene mesh (grey)

// RGB of a band: blue (band 0: shallow / not growing) through green and yellow to red (band 7).
std::array<uint8_t, 3> boxViewColour(uint32_t band);

struct BoxViewOptions {
  enum class Style { Bars, Lines };
  enum class Colour { Depth, Growth };
  Style style = Style::Bars;
  Colour colour = Colour::Depth;
  uint32_t minDepth = 0, maxDepth = std::numeric_limits<uint32_t>::max();
  double minCostShare = 0.0;  // keep nodes whose own share of the frame's cost is at least this
  double minGrowth = 0.0;     // keep nodes whose growth is at least this (needs nodeGrowth when > 0)
  float barWidth = 0.0f;      // bar thickness; 0: 1/1000 of the root box's diagonal
};

struct BoxMesh {
  std::vector<float> positions;   // xyz per vertex
  std::vector<uint8_t> bands;     // colour band per vertex
  std::vector<uint32_t> triangles;  // 3 vertex ids each
  std::vector<uint32_t> lines;      // 2 vertex ids each
  uint32_t boxCount = 0;
  uint32_t minDepth = 0, maxDepth = 0;  // of the boxes drawn
};

// Depth bands spread the drawn depth range over the 8 bands; growth bands are log2 of the node's
// growth (band 0: below 2x, band 7: 128x or more). nodeGrowth (by node, TreeQuality::nodeGrowth)
// may be empty when neither the colour nor the filter uses it.
BoxMesh buildBoxView(const Bvh& bvh, const FrameBoxes& frame, std::span<const double> nodeGrowth,
                     const BoxViewOptions& options);

// Adds a triangle mesh (3 indices per triangle over xyz positions) in the grey mesh band.
void addMeshToBoxView(BoxMesh& mesh, std::span<const uint32_t> indices, std::span<const float> positions);

// Binary little-endian PLY: vertices with uchar red/green/blue, faces, and edges for lines.
std::vector<uint8_t> encodeBoxViewPly(const BoxMesh& mesh);
// OBJ text using the materials of encodeBoxViewMtl() from the file `mtlName` (a sibling file name).
std::string encodeBoxViewObj(const BoxMesh& mesh, const std::string& mtlName);
std::string encodeBoxViewMtl();

}  // namespace tsah
