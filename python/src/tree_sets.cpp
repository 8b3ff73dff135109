// tsah.TreeSet: K trees over one animation, each used for one part of its time range (tsah/io/
// tree_set.hpp), as tsah.optimize(..., segments=...) builds them and tsah.read_tree reads them.
#include <pybind11/stl.h>

#include "anim/animation.hpp"
#include "bindings.hpp"
#include "tsah/base/files.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"

namespace tsah::python {

namespace {

using namespace pybind11::literals;

py::list rangeList(const std::vector<TimeRange>& ranges) {
  py::list out;
  for (const TimeRange& r : ranges) out.append(py::make_tuple(r.start, r.end));
  return out;
}

// The search's record of a set built in this process (the keys of `tsah optimize --segments --json`).
py::object segmentationDict(const TreeSetObject& s) {
  if (!s.optimized) return py::none();
  const SegmentationResult& r = s.search;
  py::dict out("parts"_a = rangeList(r.parts), "methods"_a = r.methods, "build_s"_a = r.buildSeconds,
               "times"_a = doubleArray(r.times), "costs"_a = doubleArray(r.costs), "average"_a = r.average,
               "maximum"_a = r.maximum, "candidate_trees_built"_a = r.treesBuilt, "search_s"_a = r.searchSeconds);
  if (!r.bound.empty()) {
    out["budget_met"] = r.budgetMet;
    out["bound"] = doubleArray(r.bound);
    out["reference_s"] = r.referenceSeconds;
    if (!r.reference.empty()) out["reference"] = doubleArray(r.reference);
  }
  return out;
}

Tree treeAt(const TreeSetObject& s, py::handle indexArg) {
  const auto count = py::ssize_t(s.set.size());
  py::ssize_t index = checkedInteger<int>(indexArg, "index");
  if (index < 0) index += count;
  if (index < 0 || index >= count) throw py::index_error("TreeSet index out of range");
  Tree tree;
  tree.file.bvh = unflattenBvh(s.set.trees[std::size_t(index)]);
  tree.file.info = s.set.builds[std::size_t(index)];
  return tree;
}

}  // namespace

TreeSetObject treeSetFromBytes(std::vector<uint8_t> bytes, tsah::TreeSet decoded) {
  TreeSetObject s;
  s.set = std::move(decoded);
  s.bytes = std::move(bytes);
  return s;
}

TreeSetObject treeSetFromOptimized(OptimizedTreeSet built) {
  TreeSetObject s;
  s.bytes = built.encode();
  s.set = built.treeSet();
  s.optimized = true;
  s.search = std::move(built.search);
  return s;
}

void bindTreeSets(py::module_& m) {
  py::class_<TreeSetObject>(m, "TreeSet", R"doc(
K trees over one animation, each built for one part of its time range: the tree of a time t is
tree_at(t) (consecutive trees switch in the middle of their overlap). Made by tsah.optimize with
segments or by tsah.read_tree of a tree-set file; len(s) trees, s[i] is a tsah.Tree (negative
indices count from the end), iterable; pickled as its .tbvh bytes.
)doc")
      .def("__len__", [](const TreeSetObject& s) { return s.set.size(); }, "The number of trees.")
      .def("__getitem__", &treeAt, "index"_a, "Tree `index` (a tsah.Tree with its own .tbvh header).")
      .def_property_readonly(
          "ranges", [](const TreeSetObject& s) { return rangeList(s.set.ranges); },
          "Each tree's build range (start, end) in seconds, in order; consecutive ones touch or overlap.")
      .def_property_readonly(
          "switch_times",
          [](const TreeSetObject& s) {
            std::vector<double> out;
            for (uint32_t i = 0; i + 1 < s.set.size(); ++i) out.push_back(switchTime(s.set.ranges, i));
            return out;
          },
          "The times where tree i hands over to tree i + 1 (the middle of their overlap).")
      .def(
          "tree_at", [](const TreeSetObject& s, double t) { return s.set.treeAt(checkedTime(t, "t")); }, "t"_a,
          "The index of the tree used at time t (on a switch time: the later tree; outside: the first or last).")
      .def_property_readonly(
          "triangle_count", [](const TreeSetObject& s) { return s.set.trees.front().triangleCount(); },
          "Triangles in every tree.")
      .def_property_readonly(
          "info",
          [](const TreeSetObject& s) {
            return py::dict("segmentation"_a = s.set.info.segmentation, "overlap"_a = s.set.info.overlap,
                            "budget"_a = s.set.info.budget, "budget_relative"_a = s.set.info.budgetRelative,
                            "trees"_a = s.set.size());
          },
          "The set's header as a dict: segmentation (single, equal, count, count-peak or budget), overlap, "
          "budget, budget_relative, trees.")
      .def_property_readonly("segmentation", &segmentationDict,
                             "For a set built in this process: the search's record (parts, methods, build_s, times, "
                             "costs, average, maximum, candidate_trees_built, search_s; with a budget budget_met, "
                             "bound, reference_s and for a relative one reference); None otherwise.")
      .def(
          "costs",
          [](const TreeSetObject& s, const anim::Animation& animation, py::handle evalFramesArg, float ct, float ci,
             py::handle threadsArg) {
            const uint32_t evalFrames = checkedInteger<uint32_t>(evalFramesArg, "eval_frames");
            const unsigned threads = checkedInteger<unsigned>(threadsArg, "threads");
            std::vector<double> costs;
            {
              py::gil_scoped_release release;
              costs = evaluateTreeSet(s.set, animation, evalFrames, {ct, ci}, threads);
            }
            return doubleArray(costs);
          },
          "animation"_a, "eval_frames"_a = 50, "ct"_a = 3.0f, "ci"_a = 2.0f, "threads"_a = 0,
          "Eq. 1 cost at eval_frames times uniform over the animation, each with the tree of its time refitted "
          "to it: float64 array (for a set built here with the same eval_frames: segmentation['costs']).")
      .def(
          "save",
          [](const TreeSetObject& s, py::handle path) { writeFileAtomically(pathArgument(path, "path"), s.bytes); },
          "path"_a, "Writes the set as one .tbvh file (atomically), what `tsah optimize --segments` writes.")
      .def(
          "to_bytes", [](const TreeSetObject& s) { return bytesObject(s.bytes); }, "The .tbvh set file's bytes.")
      // Pickled as the .tbvh bytes (the search's record is not kept).
      .def(py::pickle([](const TreeSetObject& s) { return bytesObject(s.bytes); },
                      [](const py::bytes& data) {
                        const std::string_view view = data;
                        std::vector<uint8_t> bytes(view.begin(), view.end());
                        tsah::TreeSet set = inMemory([&] { return decodeTreeSetFile(bytes, "<pickle>"); });
                        return treeSetFromBytes(std::move(bytes), std::move(set));
                      }))
      .def("__repr__", [](const TreeSetObject& s) {
        return "<tsah.TreeSet " + s.set.info.segmentation + ": " + std::to_string(s.set.size()) + " trees, " +
               std::to_string(s.set.trees.front().triangleCount()) + " triangles>";
      });
}

}  // namespace tsah::python
