#include "box_export.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "animation_frames.hpp"
#include "cli.hpp"
#include "tsah/inspect/box_view.hpp"
#include "tsah/inspect/tree_quality.hpp"

namespace tsah::cli {

std::shared_ptr<BoxExportOptions> addBoxExportOptions(CLI::App& sub) {
  auto o = std::make_shared<BoxExportOptions>();
  auto* boxes = sub.add_flag("--boxes", o->enabled,
               "Write the tree's boxes at the frame as a mesh for a viewer: -o OUT.ply or OUT.obj (docs/box-view.md)");
  // The view's options mean nothing without --boxes: refused then, not ignored.
  sub.add_option("--style", o->style, "Boxes: bars (thin bars along the edges) or lines")
      ->check(CLI::IsMember({"bars", "lines"}))
      ->needs(boxes);
  sub.add_option("--color", o->colour, "Colour by depth or by growth over the animation")
      ->check(CLI::IsMember({"depth", "growth"}))
      ->needs(boxes);
  sub.add_option("--min-depth", o->minDepth, "Boxes at this depth or deeper (root: 0)")
      ->needs(boxes);
  sub.add_option("--max-depth", o->maxDepth, "Boxes at this depth or shallower")
      ->needs(boxes);
  sub.add_option("--min-share", o->minShare, "Boxes whose own share of the frame's cost is at least this many percent")
      ->check(CLI::Range(0.0, 100.0))
      ->needs(boxes);
  sub.add_option("--min-growth", o->minGrowth,
                 "Boxes that grow at least this much over the animation (largest over smallest share of the scene)")
      ->check(CLI::Range(1.0, 1e30))
      ->needs(boxes);
  sub.add_option("--bar-width", o->barWidth, "Bar thickness (default: 1/1000 of the scene's diagonal)")
      ->check(CLI::PositiveNumber)
      ->needs(boxes);
  sub.add_option("--growth-frames", o->growthFrames, "Frames over the animation that measure growth (default 50)")
      ->check(CLI::Range(2u, 100000u))
      ->needs(boxes);
  sub.add_flag("--with-mesh", o->withMesh, "Add the animation's triangles at the frame (grey)")
      ->needs(boxes);
  return o;
}

void exportBoxes(const BoxExportOptions& o, const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info,
                 const anim::Animation& a, double time, std::span<const float> positions, const std::string& out) {
  namespace fs = std::filesystem;
  std::string ext = fs::path(out).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext != ".ply" && ext != ".obj") throw UsageError("--boxes writes a mesh: -o must end in .ply or .obj, not " + out);
  if (o.minDepth > o.maxDepth) throw UsageError("--min-depth is larger than --max-depth");

  const tsah::Bvh bvh = tsah::unflattenBvh(flat);
  const tsah::CostModel model = info.objective.cost;
  std::vector<tsah::Aabb> prims(a.triangleCount());
  tsah::triangleBoxes(a.indices(), positions, prims);
  const tsah::FrameBoxes frame = tsah::frameBoxes(bvh, prims, model);
  std::vector<double> growth;
  if (o.colour == "growth" || o.minGrowth > 0.0)
    growth = tsah::evaluateTreeQuality(bvh, animationFrames(a, a.uniformTimes(o.growthFrames)), model).nodeGrowth;

  tsah::BoxViewOptions view;
  view.style = o.style == "lines" ? tsah::BoxViewOptions::Style::Lines : tsah::BoxViewOptions::Style::Bars;
  view.colour = o.colour == "growth" ? tsah::BoxViewOptions::Colour::Growth : tsah::BoxViewOptions::Colour::Depth;
  view.minDepth = o.minDepth;
  view.maxDepth = o.maxDepth;
  view.minCostShare = o.minShare / 100.0;
  view.minGrowth = o.minGrowth;
  view.barWidth = o.barWidth;
  tsah::BoxMesh mesh = tsah::buildBoxView(bvh, frame, growth, view);
  if (mesh.boxCount == 0) throw UsageError("no box of the tree passes the depth, --min-share and --min-growth filters");
  if (o.withMesh) tsah::addMeshToBoxView(mesh, a.indices(), positions);

  std::error_code ec;
  const fs::path parent = fs::path(out).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  if (ext == ".ply") {
    tsah::writeFileAtomically(out, tsah::encodeBoxViewPly(mesh));
  } else {
    const fs::path mtl = fs::path(out).replace_extension(".mtl");
    const std::string mtlText = tsah::encodeBoxViewMtl(), objText = tsah::encodeBoxViewObj(mesh, mtl.filename().string());
    tsah::AtomicFileSet files;  // the OBJ names the MTL: both appear or neither
    files.write(mtl.string(), mtlText);
    files.write(out, objText);
    files.commit();
  }
  std::printf("wrote %s: %u boxes (depth %u..%u), coloured by %s, frame cost %.2f (time %g)\n", out.c_str(),
              mesh.boxCount, mesh.minDepth, mesh.maxDepth, o.colour.c_str(), frame.cost.total(), time);
}

}  // namespace tsah::cli
