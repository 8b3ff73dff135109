// Trees in the Python module: optimize (as `tsah optimize`), evaluate (the paper's Table 1, as
// `tsah evaluate --json`), per-frame costs, and .tbvh files.
#include <pybind11/stl.h>

#include <sstream>

#include "anim/animation.hpp"
#include "bindings.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/pipeline.hpp"
#if TSAH_HAVE_CUDA
#include "tsah/base/error.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_optimizer.hpp"
#endif

namespace tsah::python {

namespace {

using namespace pybind11::literals;

py::array_t<double> doubleArray(const std::vector<double>& values) {
  return py::array_t<double>(py::ssize_t(values.size()), values.data());
}

// The command line's options, with its defaults, as keyword arguments.
// Checked as the command line checks them (TreeOptions::validate): the limits live there.
TreeOptions treeOptions(const std::string& method, py::handle k, py::handle frames, const std::string& selection,
                        py::handle seed, float ct, float ci, py::handle maxLeaf, double timeLimit,
                        double minImprovement, py::handle threads, const std::string& optimizer,
                        const std::string& device) {
  if (device != "cpu" && device != "cuda") throw tsah::ConfigError("device: expected 'cpu' or 'cuda'");
#if TSAH_HAVE_CUDA
  if (device == "cuda" && !cuda::deviceAvailable())
    throw tsah::ConfigError("device 'cuda': no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES "
                            "hides them); use device 'cpu'");
#endif
  TreeOptions o;
  const MethodSpec spec = MethodSpec::parse(method);  // "tsah<k>" names its own k
  o.method = spec.method;
  o.objective = {method == "tsah" ? checkedInteger<int>(k, "k") : spec.k, {ct, ci},
                 checkedInteger<uint32_t>(maxLeaf, "max_leaf")};
  o.frames = checkedInteger<uint32_t>(frames, "frames");
  o.selection = parse<Selection>(selection);
  o.seed = checkedInteger<uint64_t>(seed, "seed");
  o.timeLimit = timeLimit;
  o.minImprovement = minImprovement;
  o.threads = checkedInteger<unsigned>(threads, "threads");
  o.optimizer = parse<OptimizerKind>(optimizer);
  o.device = parse<Device>(device);
#if TSAH_HAVE_CUDA
  o.gpuOptimizer = cuda::gpuTreeOptimizer();
#endif
  o.validate();
  return o;
}

py::dict infoDict(const BvhBuildInfo& info) {
  return py::dict("method"_a = info.method, "selection"_a = info.selection, "k"_a = info.objective.k,
                  "representative_frames"_a = info.representativeFrames, "seed"_a = info.seed, "ct"_a = info.objective.cost.ct,
                  "ci"_a = info.objective.cost.ci, "max_leaf_size"_a = info.objective.maxLeafSize, "build_s"_a = info.buildSeconds,
                  "time"_a = py::make_tuple(info.timeStart, info.timeEnd), "triangles"_a = info.triangleCount,
                  "vertices"_a = info.vertexCount, "topology_hash"_a = info.topologyHash);
}

py::object optimizationDict(const Tree& tree) {
  if (!tree.optimized || tree.optimization.history.empty()) return py::none();
  const InsertionOptimizer::Result& r = tree.optimization;
  py::list history;
  for (const auto& b : r.history)
    history.append(py::dict("batch"_a = b.batch, "cost"_a = b.cost, "average"_a = b.averageCost,
                            "elapsed_s"_a = b.elapsedSeconds, "steps"_a = b.steps));
  return py::dict("initial_cost"_a = r.initialCost, "final_cost"_a = r.finalCost,
                  "batches"_a = r.history.size() - 1, "steps"_a = r.steps, "accepted_steps"_a = r.acceptedSteps,
                  "seconds"_a = r.seconds, "time_limit_reached"_a = r.timeLimitReached, "history"_a = history);
}

Tree optimize(const anim::Animation& animation, const std::string& method, py::handle k, py::handle frames,
              const std::string& selection, py::handle seed, float ct, float ci, py::handle maxLeaf, double timeLimit,
              double minImprovement, py::handle threads, const std::string& optimizer, const std::string& device) {
  const TreeOptions options =
      treeOptions(method, k, frames, selection, seed, ct, ci, maxLeaf, timeLimit, minImprovement, threads, optimizer,
                  device);
  if (options.methodSpec().method == Method::SahRebuild)
    throw tsah::ConfigError("method: 'rebuild' builds one tree per frame; use tsah.evaluate for it");
  py::gil_scoped_release release;
  OptimizedTree built = optimizeAnimation(animation, options);
  Tree tree;
  tree.file.bvh = std::move(built.bvh);
  tree.file.info = std::move(built.info);
  tree.optimized = options.methodSpec().method == Method::TSah;
  tree.optimization = std::move(built.optimization);
  return tree;
}

std::vector<std::string> methodNames(py::handle methods) {
  std::vector<std::string> names;
  if (py::isinstance<py::str>(methods)) {
    std::stringstream stream(methods.cast<std::string>());
    std::string name;
    while (std::getline(stream, name, ','))
      if (!name.empty()) names.push_back(name);
  } else {
    for (py::handle m : methods) {
      if (!py::isinstance<py::str>(m)) throw ArgumentTypeError("methods: expected names (str)");
      names.push_back(m.cast<std::string>());
    }
  }
  if (names.empty()) throw tsah::ConfigError("methods: no method given");
  return names;
}

py::dict evaluate(const anim::Animation& animation, py::handle methodsArg, py::handle frames, py::handle evalFramesArg,
                  py::handle maxLeaf, float ct, float ci, const std::string& selection, py::handle seed,
                  double timeLimit, double minImprovement, py::handle threads, const std::string& optimizer,
                  const std::string& device) {
  const std::vector<std::string> names = methodNames(methodsArg);
  std::vector<MethodSpec> methods;
  for (const std::string& name : names) methods.push_back(MethodSpec::parse(name));  // ConfigError when unknown
  const uint32_t evalFrames = checkedInteger<uint32_t>(evalFramesArg, "eval_frames");
  checkEvalFrames(evalFrames);
  const TreeOptions options = treeOptions("tsah", py::int_(0), frames, selection, seed, ct, ci, maxLeaf, timeLimit,
                                          minImprovement, threads, optimizer, device);
  std::vector<MethodResult> results;
  {
    py::gil_scoped_release release;
    results = compareOnAnimation(animation, methods, options, evalFrames);
  }
  py::list rows;
  for (std::size_t m = 0; m < results.size(); ++m)
    rows.append(py::dict("name"_a = names[m], "build_s"_a = results[m].buildSeconds, "average"_a = results[m].average,
                         "maximum"_a = results[m].maximum, "per_frame"_a = doubleArray(results[m].perFrame)));
  return py::dict("input"_a = animation.name(), "triangles"_a = animation.triangleCount(),
                  "frames"_a = framesFor(animation, options.frames), "eval_frames"_a = framesFor(animation, evalFrames),
                  "max_leaf"_a = options.objective.maxLeafSize, "ct"_a = ct, "ci"_a = ci, "methods"_a = rows);
}

Tree treeFromFile(BvhFile file) {
  Tree tree;
  tree.file = std::move(file);
  return tree;
}

}  // namespace

void bindTrees(py::module_& m) {
  py::class_<Tree>(m, "Tree", R"doc(
One BVH over the triangles of an animation, with node boxes for each representative frame and the
header of its .tbvh file (how it was built). Made by tsah.optimize or tsah.read_tree.
)doc")
      .def_property_readonly("node_count", [](const Tree& t) { return t.file.bvh.nodeCount(); })
      .def_property_readonly("leaf_count", [](const Tree& t) { return t.file.bvh.leafCount(); })
      .def_property_readonly("depth", [](const Tree& t) { return t.file.bvh.depth(); })
      .def_property_readonly("triangle_count", [](const Tree& t) { return t.file.bvh.primCount(); })
      .def_property_readonly(
          "frame_count", [](const Tree& t) { return t.file.bvh.frameCount; },
          "Box sets stored per node (the representative frames).")
      .def_property_readonly(
          "info", [](const Tree& t) { return infoDict(t.file.info); },
          "The .tbvh header as a dict (the keys of `tsah info --json`).")
      .def_property_readonly("optimization", &optimizationDict,
                             "For a T-SAH tree built in this process: the optimizer's costs and batch history "
                             "(as in `tsah optimize --json`); None otherwise.")
      .def_property_readonly(
          "triangle_order",
          [](const Tree& t) {
            const FlatBvh flat = flattenBvh(t.file.bvh);
            return py::array_t<uint32_t>(py::ssize_t(flat.triIndex.size()), flat.triIndex.data());
          },
          "Triangle id of each slot of the .tbvh triangle array (leaves own consecutive slots).")
      .def(
          "frame_costs",
          [](const Tree& t, float ct, float ci) {
            Objective{0, {ct, ci}, 1}.validate("frame_costs");
            return doubleArray(frameCosts(t.file.bvh, {ct, ci}));
          },
          "ct"_a = 3.0f, "ci"_a = 2.0f, "Eq. 1 cost at each stored (representative) frame, float64 array.")
      .def(
          "costs",
          [](const Tree& t, const anim::Animation& animation, py::handle evalFramesArg, py::object ct, py::object ci,
             py::handle threadsArg) {
            const uint32_t evalFrames = checkedInteger<uint32_t>(evalFramesArg, "eval_frames");
            const unsigned threads = checkedInteger<unsigned>(threadsArg, "threads");
            const CostModel cost{ct.is_none() ? t.file.info.objective.cost.ct : ct.cast<float>(),
                                 ci.is_none() ? t.file.info.objective.cost.ci : ci.cast<float>()};
            std::vector<double> costs;
            {
              py::gil_scoped_release release;
              costs = evaluateAnimation(t.file.bvh, animation, evalFrames, cost, threads);
            }
            return doubleArray(costs);
          },
          "animation"_a, "eval_frames"_a = 50, "ct"_a = py::none(), "ci"_a = py::none(), "threads"_a = 0,
          R"doc(Eq. 1 cost of the tree refitted to eval_frames frames uniform over the animation (1 for a
static input): float64 array, the per_frame costs of `tsah optimize --json`. ct, ci: the tree's own by default.)doc")
      .def(
          "save", [](const Tree& t, const std::string& path) { saveBvhFile(path, t.file.bvh, t.file.info); }, "path"_a,
          "Writes the tree as a .tbvh file (atomically), byte for byte what `tsah optimize` writes.")
      .def(
          "to_bytes",
          [](const Tree& t) {
            const std::vector<uint8_t> bytes = encodeBvhFile(t.file.bvh, t.file.info);
            return py::bytes(reinterpret_cast<const char*>(bytes.data()), bytes.size());
          },
          "The .tbvh file's bytes.")
      .def("__repr__", [](const Tree& t) {
        return "<tsah.Tree " + t.file.info.method + ": " + std::to_string(t.file.bvh.primCount()) + " triangles, " +
               std::to_string(t.file.bvh.nodeCount()) + " nodes, " + std::to_string(t.file.bvh.frameCount) + " frames>";
      });

  m.def(
      "read_tree", [](const std::string& path) { return treeFromFile(loadBvhFile(path)); }, "path"_a,
      "Reads and validates a .tbvh file; raises tsah.FileError ('FILE: problem') when it is not a valid tree.");
  m.def(
      "tree_from_bytes",
      [](const py::bytes& data, const std::string& name) {
        const std::string_view view = data;
        return treeFromFile(decodeBvhFile({reinterpret_cast<const uint8_t*>(view.data()), view.size()}, name));
      },
      "data"_a, "name"_a = "<bytes>", "A tree from the bytes of a .tbvh file (validated as read_tree does).");

  m.def("optimize", &optimize, "animation"_a, "method"_a = "tsah", "k"_a = 0, "frames"_a = 5, "selection"_a = "mh",
        "seed"_a = 1, "ct"_a = 3.0f, "ci"_a = 2.0f, "max_leaf"_a = 8, "time_limit"_a = 0.0,
        "min_improvement"_a = InsertionOptimizer::Config{}.minImprovement, "threads"_a = 0,
        "optimizer"_a = "sequential", "device"_a = "cpu", R"doc(
One tree for the whole animation, exactly as `tsah optimize` builds it (same options, same defaults;
the same seed gives the same tree and the same .tbvh bytes apart from the build time field).
  optimizer  'sequential' (the paper's insertion optimizer) or 'parallel' (parallel reinsertion on
             `threads` cores, 0: all; the same tree for any thread count)
  device     'cpu', or 'cuda': the parallel reinsertion optimizer on the GPU (tsah.ConfigError in a build
             without CUDA or on a machine without a device)
  method     'tsah' (optimized for all frames), 'sah0' (frame 0, refitted) or 'sahstar' (best over time)
  k          T-SAH exponent (0: average cost; larger: the worst frames weigh more)
  frames     representative frames, uniform in time (1 for a static input)
  selection  'mh' (Metropolis-Hastings), 'random' or 'batch'
  max_leaf   largest leaf after the adaptive collapse
Raises tsah.ConfigError (a ValueError) for an unknown method or selection, tsah.DataError when the
animation has no triangles.
)doc");

  m.def("evaluate", &evaluate, "animation"_a, "methods"_a = "sah0,sahstar,tsah0,tsah2,tsah4,rebuild", "frames"_a = 5,
        "eval_frames"_a = 50, "max_leaf"_a = 8, "ct"_a = 3.0f, "ci"_a = 2.0f, "selection"_a = "mh", "seed"_a = 1,
        "time_limit"_a = 0.0, "min_improvement"_a = InsertionOptimizer::Config{}.minImprovement, "threads"_a = 0,
        "optimizer"_a = "sequential", "device"_a = "cpu", R"doc(
The paper's Table 1 for one animation, as `tsah evaluate --json` computes it: a dict with input,
triangles, frames, eval_frames, max_leaf, ct, ci and methods, a list of dicts (name, build_s,
average, maximum, per_frame: float64 array of the cost at each evaluation frame).
  methods    comma-separated names or a list of them: sah0, sahstar, rebuild, tsah<k>
  optimizer  'sequential' or 'parallel': which optimizer builds the T-SAH, SAH* and rebuild trees
  device     'cpu', or 'cuda': all of them by the GPU parallel reinsertion optimizer
)doc");
}

}  // namespace tsah::python
