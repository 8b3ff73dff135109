// Trees in the Python module: optimize (as `tsah optimize`, one tree or a tree set), evaluate (the
// paper's Table 1, as `tsah evaluate --json`), per-frame costs, and .tbvh files (read_tree,
// tree_from_bytes, pickling). The TreeSet class is in tree_sets.cpp.
#include <pybind11/stl.h>

#include <sstream>

#include "anim/animation.hpp"
#include "bindings.hpp"
#include "tsah/base/files.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/pipeline.hpp"
#if TSAH_HAVE_CUDA
#include "tsah/base/error.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_optimizer.hpp"
#endif

namespace tsah::python {

py::array_t<double> doubleArray(const std::vector<double>& values) {
  return py::array_t<double>(py::ssize_t(values.size()), values.data());
}

py::bytes bytesObject(std::span<const uint8_t> bytes) {
  return py::bytes(reinterpret_cast<const char*>(bytes.data()), bytes.size());
}

namespace {

using namespace pybind11::literals;

}  // namespace

// The command line's options, with its defaults, as keyword arguments, checked as the command
// line checks them (TreeOptions::validate: the limits live there). optimizer 'gpu' is the command
// line's --device cuda (parallel reinsertion on the GPU).
TreeOptions treeOptions(const std::string& method, py::handle k, py::handle frames, const std::string& selection,
                        py::handle seed, float ct, float ci, py::handle maxLeaf, double timeLimit,
                        double minImprovement, py::handle threads, const std::string& optimizer) {
  TreeOptions o;
  if (optimizer == "gpu") {
#if TSAH_HAVE_CUDA
    if (!cuda::deviceAvailable())
      throw tsah::ConfigError("optimizer='gpu': no CUDA device found (no GPU, no NVIDIA driver, or "
                              "CUDA_VISIBLE_DEVICES hides them); use optimizer='parallel'");
    o.gpuOptimizer = cuda::gpuTreeOptimizer();
#else
    throw tsah::ConfigError("optimizer='gpu': this build of tsah has no CUDA support (tsah.cuda_built is False); "
                            "use optimizer='parallel'");
#endif
    o.device = Device::Cuda;
    o.optimizer = OptimizerKind::Parallel;
  } else if (optimizer == "sequential" || optimizer == "parallel") {
    o.optimizer = parse<OptimizerKind>(optimizer);
  } else {
    throw tsah::ConfigError("optimizer: unknown optimizer '" + optimizer + "' (expected sequential, parallel or gpu)");
  }
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
  o.validate();
  return o;
}

namespace {

// The progress events handed to Python's callback: a dict with "message" (text), and for an
// optimizer batch its record.
py::dict messageEvent(const std::string& message) { return py::dict("message"_a = message); }
py::dict batchDict(const InsertionOptimizer::BatchRecord& r) {
  return py::dict("batch"_a = r.batch, "cost"_a = r.cost, "average"_a = r.averageCost, "elapsed_s"_a = r.elapsedSeconds,
                  "steps"_a = r.steps);
}
py::dict batchEvent(const InsertionOptimizer::BatchRecord& r) {
  py::dict event = batchDict(r);
  event["message"] = "batch " + std::to_string(r.batch) + ", cost " + std::to_string(r.cost);
  return event;
}

}  // namespace

// Hooks `call` into the options: its cancel check, and (with a callback) progress of the given kind.
void connect(TreeOptions& options, LongCall& call, bool batches) {
  options.cancelled = call.cancelled();
  if (!call.reports()) return;
  if (batches)
    options.batchProgress = [&call](const InsertionOptimizer::BatchRecord& r) { call.report([r] { return batchEvent(r); }); };
  else
    options.progress = [&call](const std::string& m) { call.report([m] { return messageEvent(m); }); };
}

namespace {

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
  for (const auto& b : r.history) history.append(batchDict(b));
  return py::dict("initial_cost"_a = r.initialCost, "final_cost"_a = r.finalCost,
                  "batches"_a = r.history.size() - 1, "steps"_a = r.steps, "accepted_steps"_a = r.acceptedSteps,
                  "seconds"_a = r.seconds, "time_limit_reached"_a = r.timeLimitReached, "history"_a = history);
}


// A float option given as None (not given) or a number; refused with `name` when given without a
// tree set.
double setOption(py::handle value, const char* name, bool isSet, double otherwise) {
  if (value.is_none()) return otherwise;
  if (!isSet) throw tsah::ConfigError(std::string(name) + ": goes with segments (a tree set)");
  if (!PyNumber_Check(value.ptr()) || py::isinstance<py::bool_>(value) || py::isinstance<py::str>(value))
    throw ArgumentTypeError(std::string(name) + ": expected a number, got " +
                            std::string(py::str(value.get_type().attr("__name__"))));
  return value.cast<double>();
}

// tsah optimize --segments K|auto: the set options of the keyword arguments.
TreeSetOptions treeSetOptions(const TreeOptions& tree, py::handle segments, py::handle budget, py::handle budgetCost,
                              py::handle overlap, py::handle evalFrames, py::handle referenceFrames,
                              py::handle maxTrees) {
  TreeSetOptions o;
  o.tree = tree;
  const bool isAuto = py::isinstance<py::str>(segments) && segments.cast<std::string>() == "auto";
  if (py::isinstance<py::str>(segments) && !isAuto)
    throw tsah::ConfigError("segments: expected a number of trees or 'auto', got '" + segments.cast<std::string>() + "'");
  o.segments = isAuto ? 0u : checkedInteger<uint32_t>(segments, "segments", 1, TreeSetOptions::kMaxSegments);
  o.budget = setOption(budget, "budget", true, 0.0);
  o.budgetCost = setOption(budgetCost, "budget_cost", true, 0.0);
  o.overlap = setOption(overlap, "overlap", true, 0.0);
  if (!evalFrames.is_none()) o.evalFrames = checkedInteger<uint32_t>(evalFrames, "eval_frames");
  if (!referenceFrames.is_none()) o.referenceFrames = checkedInteger<uint32_t>(referenceFrames, "reference_frames");
  if (!maxTrees.is_none()) o.maxTrees = checkedInteger<uint32_t>(maxTrees, "max_trees");
  if (!isAuto && (!referenceFrames.is_none() || !maxTrees.is_none()))
    throw tsah::ConfigError(std::string(maxTrees.is_none() ? "reference_frames" : "max_trees") +
                            ": goes with segments='auto' (the budget search)");
  o.validate();
  return o;
}

py::object optimize(const anim::Animation& animation, const std::string& method, py::handle k, py::handle frames,
                    const std::string& selection, py::handle seed, float ct, float ci, py::handle maxLeaf,
                    double timeLimit, double minImprovement, py::handle threads, const std::string& optimizer,
                    py::handle segments, py::handle budget, py::handle budgetCost, py::handle overlap,
                    py::handle evalFrames, py::handle referenceFrames, py::handle maxTrees, bool reproducible,
                    py::object progress) {
  TreeOptions options = treeOptions(method, k, frames, selection, seed, ct, ci, maxLeaf, timeLimit, minImprovement,
                                    threads, optimizer);
  if (options.methodSpec().method == Method::SahRebuild)
    throw tsah::ConfigError("method: 'rebuild' builds one tree per frame; use tsah.evaluate for it");
  LongCall call(std::move(progress));
  if (!segments.is_none()) {
    connect(options, call, false);
    TreeSetOptions setOptions =
        treeSetOptions(options, segments, budget, budgetCost, overlap, evalFrames, referenceFrames, maxTrees);
    setOptions.reproducible = reproducible;
    OptimizedTreeSet set = call.run([&] { return optimizeTreeSet(animation, setOptions); });
    return py::cast(treeSetFromOptimized(std::move(set)));
  }
  const std::initializer_list<std::pair<py::handle, const char*>> setOnly = {
      {budget, "budget"},           {budgetCost, "budget_cost"},           {overlap, "overlap"},
      {evalFrames, "eval_frames"}, {referenceFrames, "reference_frames"}, {maxTrees, "max_trees"}};
  for (const auto& [value, name] : setOnly)
    if (!value.is_none()) throw tsah::ConfigError(std::string(name) + ": goes with segments (a tree set)");
  connect(options, call, true);
  OptimizedTree built = call.run([&] { return optimizeAnimation(animation, options); });
  Tree tree;
  tree.file.bvh = std::move(built.bvh);
  tree.file.info = std::move(built.info);
  if (reproducible) tree.file.info.buildSeconds = 0.0;
  tree.optimized = options.methodSpec().method == Method::TSah;
  tree.optimization = std::move(built.optimization);
  return py::cast(std::move(tree));
}

std::vector<std::string> methodNames(py::handle methods) {
  std::vector<std::string> names;
  if (py::isinstance<py::str>(methods)) {
    std::stringstream stream(methods.cast<std::string>());
    std::string name;
    while (std::getline(stream, name, ','))
      if (!name.empty()) names.push_back(name);
  } else {
    if (!py::isinstance<py::iterable>(methods))
      throw ArgumentTypeError("methods: expected a str or a sequence of names, got " +
                              std::string(py::str(methods.get_type().attr("__name__"))));
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
                  py::object progress) {
  const std::vector<std::string> names = methodNames(methodsArg);
  std::vector<MethodSpec> methods;
  for (const std::string& name : names) methods.push_back(MethodSpec::parse(name));  // ConfigError when unknown
  const uint32_t evalFrames = checkedInteger<uint32_t>(evalFramesArg, "eval_frames");
  checkEvalFrames(evalFrames);
  TreeOptions options = treeOptions("tsah", py::int_(0), frames, selection, seed, ct, ci, maxLeaf, timeLimit,
                                    minImprovement, threads, optimizer);
  LongCall call(std::move(progress));
  connect(options, call, false);
  const std::vector<MethodResult> results =
      call.run([&] { return compareOnAnimation(animation, methods, options, evalFrames); });
  py::list rows;
  for (std::size_t m = 0; m < results.size(); ++m)
    rows.append(py::dict("name"_a = names[m], "build_s"_a = results[m].buildSeconds, "average"_a = results[m].average,
                         "maximum"_a = results[m].maximum, "per_frame"_a = doubleArray(results[m].perFrame)));
  return py::dict("input"_a = animation.name(), "triangles"_a = animation.triangleCount(),
                  "frames"_a = framesFor(animation, options.frames), "eval_frames"_a = framesFor(animation, evalFrames),
                  "max_leaf"_a = options.objective.maxLeafSize, "ct"_a = ct, "ci"_a = ci, "methods"_a = rows);
}

// A .tbvh file's bytes as read_tree returns them: a Tree for a file of one tree (version 1), a
// TreeSet for a set file (version 2). decodeTreeSetFile validates either kind.
py::object treeOrSet(std::vector<uint8_t> bytes, const std::string& name) {
  TreeSet set;
  {
    py::gil_scoped_release release;
    set = decodeTreeSetFile(bytes, name);
  }
  if (set.version == kTbvhSetVersion) return py::cast(treeSetFromBytes(std::move(bytes), std::move(set)));
  Tree tree;
  tree.file = decodeBvhFile(bytes, name);
  return py::cast(std::move(tree));
}

py::object treeFromBytes(py::handle data, const std::string& name) {
  if (!py::isinstance<py::bytes>(data) && !py::isinstance<py::bytearray>(data) &&
      !py::isinstance<py::memoryview>(data))
    throw ArgumentTypeError("data: expected bytes, got " + std::string(py::str(data.get_type().attr("__name__"))));
  const std::string text = py::bytes(py::module_::import("builtins").attr("bytes")(data));
  return inMemory([&] { return treeOrSet(std::vector<uint8_t>(text.begin(), text.end()), name); });
}

}  // namespace

void bindTrees(py::module_& m) {
  py::class_<Tree>(m, "Tree", R"doc(
One BVH over the triangles of an animation, with node boxes for each representative frame and the
header of its .tbvh file (how it was built). Made by tsah.optimize, tsah.read_tree or TreeSet[i];
pickled as its .tbvh bytes.
)doc")
      .def_property_readonly(
          "node_count", [](const Tree& t) { return t.file.bvh.nodeCount(); }, "Nodes of the tree (interior and leaves).")
      .def_property_readonly(
          "leaf_count", [](const Tree& t) { return t.file.bvh.leafCount(); }, "Leaves of the tree.")
      .def_property_readonly(
          "depth", [](const Tree& t) { return t.file.bvh.depth(); }, "Depth of the deepest leaf (the root: 0).")
      .def_property_readonly(
          "triangle_count", [](const Tree& t) { return t.file.bvh.primCount(); }, "Triangles in the tree.")
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
          "save",
          [](const Tree& t, py::handle path) { saveBvhFile(pathArgument(path, "path"), t.file.bvh, t.file.info); },
          "path"_a, "Writes the tree as a .tbvh file (atomically), byte for byte what `tsah optimize` writes.")
      .def(
          "to_bytes", [](const Tree& t) { return bytesObject(encodeBvhFile(t.file.bvh, t.file.info)); },
          "The .tbvh file's bytes.")
      // Pickled as the .tbvh bytes (the optimizer's record is not kept).
      .def(py::pickle([](const Tree& t) { return bytesObject(encodeBvhFile(t.file.bvh, t.file.info)); },
                      [](const py::bytes& data) {
                        const std::string_view view = data;
                        Tree tree;
                        tree.file = inMemory([&] {
                          return decodeBvhFile({reinterpret_cast<const uint8_t*>(view.data()), view.size()}, "<pickle>");
                        });
                        return tree;
                      }))
      .def("__repr__", [](const Tree& t) {
        return "<tsah.Tree " + t.file.info.method + ": " + std::to_string(t.file.bvh.primCount()) + " triangles, " +
               std::to_string(t.file.bvh.nodeCount()) + " nodes, " + std::to_string(t.file.bvh.frameCount) + " frames>";
      });

  bindTreeSets(m);

  m.def(
      "read_tree",
      [](py::handle pathArg) {
        const std::string path = pathArgument(pathArg, "path");
        std::vector<uint8_t> bytes;
        {
          py::gil_scoped_release release;
          bytes = readFile(path);
        }
        return treeOrSet(std::move(bytes), path);
      },
      "path"_a, R"doc(
Reads and validates a .tbvh file, whichever `tsah optimize` wrote: a Tree for a file of one tree, a
TreeSet for a tree-set file (`--segments`, or tsah.optimize with segments). Raises tsah.FileError
('FILE: problem') when it is not a valid tree file.
)doc");
  m.def("tree_from_bytes", &treeFromBytes, "data"_a, "name"_a = "<bytes>", R"doc(
A Tree or a TreeSet from the bytes of a .tbvh file (validated as read_tree does; pickling uses it).
Raises tsah.DataError ('NAME: problem') when the bytes are not a valid tree file.
)doc");

  m.def("optimize", &optimize, "animation"_a, "method"_a = "tsah", "k"_a = 0, "frames"_a = 5, "selection"_a = "mh",
        "seed"_a = 1, "ct"_a = 3.0f, "ci"_a = 2.0f, "max_leaf"_a = 8, "time_limit"_a = 0.0,
        "min_improvement"_a = InsertionOptimizer::Config{}.minImprovement, "threads"_a = 0,
        "optimizer"_a = "sequential", "segments"_a = py::none(), "budget"_a = py::none(),
        "budget_cost"_a = py::none(), "overlap"_a = py::none(), "eval_frames"_a = py::none(),
        "reference_frames"_a = py::none(), "max_trees"_a = py::none(), "reproducible"_a = false,
        "progress"_a = py::none(), R"doc(
One tree for the whole animation, exactly as `tsah optimize` builds it (same options, same defaults;
the same seed gives the same tree and the same .tbvh bytes apart from the build time field), or with
segments a TreeSet, as `tsah optimize --segments` builds it.
  method     'tsah' (optimized for all frames), 'sah0' (frame 0, refitted) or 'sahstar' (best over time)
  k          T-SAH exponent (0: average cost; larger: the worst frames weigh more)
  frames     representative frames, uniform in time (1 for a static input)
  selection  'mh' (Metropolis-Hastings), 'random' or 'batch'
  max_leaf   largest leaf after the adaptive collapse
  optimizer  'sequential' (the paper's insertion optimizer), 'parallel' (parallel reinsertion on
             `threads` cores, 0: all; the same tree for any thread count) or 'gpu' (parallel
             reinsertion on the GPU; tsah.ConfigError in a build without CUDA or without a device)
  segments   None: one Tree; K (1..1000): a TreeSet of K trees with the split points that minimize
             the average cost (the peak with k > 0); 'auto': the fewest trees that keep every
             evaluation frame within budget (default 1.05: x a per-frame optimized SAH tree's cost)
             or within budget_cost (an absolute cost); at most max_trees trees (64); the reference
             from reference_frames (10) per-frame trees, linear in between
  overlap    seconds shared by consecutive trees of a set (each built for its part widened by half)
  eval_frames  a set's evaluation frames, where costs are measured (default 50)
  reproducible  record every build time as 0: the same bytes on every run
  progress   a callable, called on this thread with a dict for each event: 'message' (text) and, for
             a single tree's optimizer batches, 'batch', 'cost', 'average', 'elapsed_s', 'steps';
             an exception in it cancels the call and propagates
Ctrl-C stops the optimization within a fraction of a second (KeyboardInterrupt).
Raises tsah.ConfigError (a ValueError) for an unknown method, selection or optimizer and options out
of range, tsah.DataError when the animation has no triangles (or, for a set, one frame).
)doc");

  m.def("evaluate", &evaluate, "animation"_a, "methods"_a = "sah0,sahstar,tsah0,tsah2,tsah4,rebuild", "frames"_a = 5,
        "eval_frames"_a = 50, "max_leaf"_a = 8, "ct"_a = 3.0f, "ci"_a = 2.0f, "selection"_a = "mh", "seed"_a = 1,
        "time_limit"_a = 0.0, "min_improvement"_a = InsertionOptimizer::Config{}.minImprovement, "threads"_a = 0,
        "optimizer"_a = "sequential", "progress"_a = py::none(), R"doc(
The paper's Table 1 for one animation, as `tsah evaluate --json` computes it: a dict with input,
triangles, frames, eval_frames, max_leaf, ct, ci and methods, a list of dicts (name, build_s,
average, maximum, per_frame: float64 array of the cost at each evaluation frame).
  methods    comma-separated names or a list of them: sah0, sahstar, rebuild, tsah<k>
  optimizer  'sequential', 'parallel' or 'gpu': which optimizer builds the T-SAH, SAH* and rebuild trees
  progress   a callable, called on this thread with a dict {'message': text} per step; an exception
             in it cancels the call and propagates
Ctrl-C stops the work within a fraction of a second (KeyboardInterrupt).
)doc");
}

}  // namespace tsah::python
