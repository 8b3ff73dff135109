// tsah evaluate INPUT [--methods sah0,sahstar,tsah0,tsah2,tsah4,rebuild] [--frames 5]
//   [--eval-frames 50] [--max-leaf 8] [--ct 3] [--ci 2] [--selection mh] [--seed S]
//   [--time-limit SEC] [--threads T] [--json]
// The paper's Table 1 for one input: build time, average and maximum cost of every method over the
// evaluation frames, each tree refitted to every frame (SAH-rebuild: one tree per frame).
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli.hpp"
#include "optimizer_options.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/pipeline.hpp"

namespace {

struct Options {
  tsah::TreeOptions tree;  // method, k, frames, selection, seed, ct, ci, maxLeaf, limits, threads
  std::string input;
  std::string methods = "sah0,sahstar,tsah0,tsah2,tsah4,rebuild";
  uint32_t evalFrames = 50;
  bool json = false;
};


std::vector<tsah::MethodSpec> parseMethods(const std::string& list, std::vector<std::string>& names) {
  std::vector<tsah::MethodSpec> methods;
  std::stringstream stream(list);
  std::string name;
  while (std::getline(stream, name, ',')) {
    if (name.empty()) continue;
    try {
      methods.push_back(tsah::MethodSpec::parse(name));
    } catch (const tsah::ConfigError& e) {
      throw tsah::cli::UsageError(std::string("--methods: ") + e.what());
    }
    names.push_back(name);
  }
  if (methods.empty()) throw tsah::cli::UsageError("--methods: no method given");
  return methods;
}


void run(const Options& opt) {
  std::vector<std::string> names;  // as written in --methods (e.g. "tsah" stays "tsah")
  const std::vector<tsah::MethodSpec> methods = parseMethods(opt.methods, names);
  tsah::cli::checkTreeDevice(opt.tree);
  const anim::Animation a = tsah::cli::loadInput(opt.input);
  if (a.triangleCount() == 0) throw tsah::cli::UsageError(opt.input + ": no triangles to build a tree over");
  const uint32_t frames = tsah::framesFor(a, opt.tree.frames);
  const uint32_t evalFrames = tsah::framesFor(a, opt.evalFrames);

  tsah::cli::Progress progress("evaluate");
  tsah::TreeOptions treeOpt = opt.tree;
  treeOpt.progress = [&](const std::string& message) { progress.message(message); };
  const std::vector<tsah::MethodResult> results = tsah::compareOnAnimation(a, methods, treeOpt, opt.evalFrames);

  nlohmann::json j;
  j["input"] = opt.input;
  j["triangles"] = a.triangleCount();
  j["frames"] = frames;
  j["eval_frames"] = evalFrames;
  j["max_leaf"] = opt.tree.maxLeaf;
  j["ct"] = opt.tree.ct;
  j["ci"] = opt.tree.ci;
  j["methods"] = nlohmann::json::array();
  for (std::size_t m = 0; m < results.size(); ++m)
    j["methods"].push_back({{"name", names[m]},
                            {"build_s", results[m].buildSeconds},
                            {"average", results[m].average},
                            {"maximum", results[m].maximum},
                            {"per_frame", results[m].perFrame}});
  progress.message("done");
  if (opt.json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%s: %u triangles, %u representative frames, %u evaluation frames, cT=%g cI=%g, max leaf %u\n",
              opt.input.c_str(), a.triangleCount(), frames, evalFrames, double(opt.tree.ct), double(opt.tree.ci), opt.tree.maxLeaf);
  std::printf("%-10s %10s %10s %10s\n", "method", "build [s]", "cost", "max cost");
  for (std::size_t m = 0; m < results.size(); ++m)
    std::printf("%-10s %10.2f %10.2f %10.2f\n", names[m].c_str(), results[m].buildSeconds, results[m].average,
                results[m].maximum);
}

}  // namespace

TSAH_REGISTER_COMMAND(45, [](CLI::App& app) {
  auto* sub = app.add_subcommand("evaluate", "Compare SAH0, SAH*, SAH-rebuild and T-SAH on an input (the paper's Table 1)");
  auto opt = std::make_shared<Options>();
  sub->add_option("INPUT", opt->input, "Animation or static mesh (any input `tsah info` reads)")->required();
  sub->add_option("--methods", opt->methods, "Comma-separated: sah0, sahstar, rebuild, tsah<k> (tsah0, tsah2, ...)")
      ->capture_default_str();
  tsah::cli::addTreeOptions(*sub, opt->tree, opt->evalFrames);
  sub->add_flag("--json", opt->json, "Print one JSON object");
  sub->callback([opt] { run(*opt); });
});
