#include "bench/scaling.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/tanim.hpp"
#include "bench/plot.hpp"
#include "bench/process.hpp"
#include "bench/report.hpp"

namespace tsah::bench {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Input {
  std::string name, path, kind;
};

double loadAverage() {
  double load[1] = {0.0};
  return ::getloadavg(load, 1) == 1 ? load[0] : -1.0;
}

// One `tsah optimize --json` child: its report, wall time, CPU time and peak memory.
json optimizeOnce(const Input& input, const std::string& optimizer, const ScalingOptions& o, const fs::path& work) {
  const fs::path tree = work / "scaling-tree.tbvh", report = work / "scaling-report.json";
  // "cuda": the GPU parallel reinsertion optimizer (--device cuda); the others are --optimizer names.
  // The optimizers scale on one flat tree: a scene file's default structure may be two-level.
  const bool gpu = optimizer == "cuda";
  const std::vector<std::string> argv = {o.program, "optimize", input.path, "-o", tree.string(), "--optimizer",
                                         gpu ? "parallel" : optimizer, "--device", gpu ? "cuda" : "cpu",
                                         "--threads", std::to_string(o.threads), "--frames", std::to_string(o.frames),
                                         "--eval-frames", std::to_string(o.evalFrames), "--seed", std::to_string(o.seed),
                                         "--structure", "flat", "--json"};
  const double load = loadAverage();
  const auto start = std::chrono::steady_clock::now();
  const ProcessResult r = runProcess(argv, report.string());
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::error_code ec;
  fs::remove(tree, ec);
  if (!r.ok())
    throw tsah::Failure(input.path + ": tsah optimize --optimizer " + optimizer + " failed" +
                        (r.output.empty() ? "" : ": " + r.output.substr(0, r.output.find('\n'))));
  std::ifstream in(report);
  const json j = json::parse(in, nullptr, false);
  fs::remove(report, ec);
  if (j.is_discarded() || !j.contains("optimization"))
    throw tsah::Failure(input.path + ": unreadable tsah optimize report");
  const double triangles = j["triangles"].get<double>();
  // The child's own high-water mark: wait4's ru_maxrss also counts this process, whose memory the
  // child shared until it started the program.
  const double peak = j.value("peak_rss_bytes", 0.0) > 0.0 ? j["peak_rss_bytes"].get<double>() : double(r.maxRssKb) * 1024.0;
  return {{"input", input.name},
          {"path", input.path},
          {"kind", input.kind},
          {"triangles", j["triangles"]},
          {"optimizer", optimizer},
          {"threads", o.threads},
          {"optimize_s", j["optimization"]["seconds"]},
          {"command_s", wall},
          {"cpu_s", r.cpuSeconds},
          {"peak_rss_bytes", peak},
          {"bytes_per_triangle", peak / triangles},
          {"initial_cost", j["optimization"]["initial_cost"]},
          {"final_cost", j["optimization"]["final_cost"]},
          {"eval_average", j["cost"]["average"]},
          {"load_average", load}};
}

std::string fixed(double v, int d) { return formatFixed(v, d); }

}  // namespace

json runScaling(const std::vector<SceneSource>& scenes, const ScalingOptions& o, const fs::path& outDir,
                const std::function<void(const std::string&)>& progress) {
  const fs::path work = outDir / "scaling";
  std::error_code ec;
  fs::create_directories(work, ec);
  if (ec) throw tsah::Failure(work.string() + ": cannot create the folder");
  std::vector<Input> inputs;
  for (uint32_t n : o.sizes) {
    const std::string name = "explode-" + std::to_string(n);
    const fs::path file = work / (name + "-k" + std::to_string(o.keyframes) + "-s" + std::to_string(o.seed) + ".tanim");
    if (!fs::exists(file, ec)) {
      progress("generating " + name);
      anim::saveTanim(anim::generate(anim::GeneratorKind::Explode, {n, o.keyframes, o.seed}), file.string());
    }
    inputs.push_back({name, file.string(), "generated"});
  }
  for (const SceneSource& s : scenes) inputs.push_back({s.name, s.input, "scene"});

  json rows = json::array();
  for (const Input& input : inputs)
    for (const std::string& optimizer : o.optimizers) {
      progress("optimizing " + input.name + " (" + optimizer + ")");
      rows.push_back(optimizeOnce(input, optimizer, o, work));
    }
  return {{"mode", "scaling"},
          {"frames", o.frames},
          {"eval_frames", o.evalFrames},
          {"keyframes", o.keyframes},
          {"seed", o.seed},
          {"threads", o.threads},
          {"optimizers", o.optimizers},
          {"rows", rows}};
}

std::string renderScalingMarkdown(const json& results) {
  std::ostringstream md;
  md << "# tsah bench --scaling\n\n";
  if (results.contains("command")) md << "`" << results["command"].get<std::string>() << "`";
  if (results.contains("machine") && results["machine"].contains("cpu"))
    md << " on " << results["machine"]["cpu"].dump();
  const unsigned threads = results.value("threads", 0u);
  md << "\n\nEvery row is one `tsah optimize --json` process (" << results.value("frames", 5)
     << " representative frames, " << (threads ? std::to_string(threads) + " threads" : std::string("all cores"))
     << "): optimize s is the optimizer's own time, command s and CPU s the whole "
        "process's, peak its maximum resident memory. Final cost: T-SAH C~^k with one triangle per "
        "leaf; ratio: that cost over the sequential optimizer's on the same input. The load average "
        "was read as each row started (the machine may be shared: compare rows run under the same load).\n\n";
  md << "| input | triangles | optimizer | optimize s | command s | CPU s | peak MiB | B/triangle | final cost | ratio | load |\n";
  md << "|---|--:|---|--:|--:|--:|--:|--:|--:|--:|--:|\n";
  std::map<std::string, double> sequential;
  for (const json& r : results["rows"])
    if (r["optimizer"] == "sequential") sequential[r["input"].get<std::string>()] = r["final_cost"].get<double>();
  for (const json& r : results["rows"]) {
    const auto it = sequential.find(r["input"].get<std::string>());
    const std::string ratio =
        it == sequential.end() || r["optimizer"] == "sequential" ? "" : fixed(r["final_cost"].get<double>() / it->second, 4);
    md << "| " << r["input"].get<std::string>() << " | " << r["triangles"].get<uint64_t>() << " | "
       << r["optimizer"].get<std::string>() << " | " << formatSignificant(r["optimize_s"].get<double>()) << " | "
       << formatSignificant(r["command_s"].get<double>()) << " | " << formatSignificant(r["cpu_s"].get<double>()) << " | "
       << fixed(r["peak_rss_bytes"].get<double>() / 1048576.0, 1) << " | " << fixed(r["bytes_per_triangle"].get<double>(), 0)
       << " | " << fixed(r["final_cost"].get<double>(), 3) << " | " << ratio << " | "
       << fixed(r["load_average"].get<double>(), 2) << " |\n";
  }
  if (results.contains("plots")) {
    md << "\n";
    for (const json& p : results["plots"]) md << "![" << p.get<std::string>() << "](" << p.get<std::string>() << ")\n";
  }
  if (results.contains("plot_status")) md << "\nPlots: " << results["plot_status"].get<std::string>() << "\n";
  return md.str();
}

void makeScalingPlots(json& results, const fs::path& outDir) {
  results["plots"] = json::array();
  if (gnuplotVersion().empty()) {
    results["plot_status"] = "skipped: gnuplot is not installed";
    return;
  }
  const fs::path dir = outDir / "plots";
  std::error_code ec;
  fs::create_directories(dir, ec);
  Plotter plotter(dir, plotTerminal(cairoAvailable()));
  // One line per optimizer over the generated sizes, one set of points per optimizer for the scenes.
  auto seriesOf = [&](const char* key) {
    std::vector<Series> series;
    for (const json& name : results["optimizers"])
      for (const char* kind : {"generated", "scene"}) {
        Series s{name.get<std::string>() + (std::string(kind) == "scene" ? " (real scenes)" : " (explode)"), {}, {},
                 std::string(kind) == "scene"};
        for (const json& r : results["rows"])
          if (r["optimizer"] == name && r["kind"] == kind) {
            s.x.push_back(r["triangles"].get<double>());
            s.y.push_back(r[key].get<double>());
          }
        series.push_back(s);
      }
    return series;
  };
  std::vector<std::string> errors;
  auto emit = [&](const std::string& suffix, const std::string& title, const std::string& yl, const char* key, bool logY) {
    std::string error;
    if (plotter.plot("scaling-" + suffix, title, "triangles", yl, seriesOf(key), logY, error, /*logX=*/true))
      results["plots"].push_back("plots/scaling-" + suffix + ".png");
    else
      errors.push_back(error);
  };
  emit("time", "Optimization time", "seconds (optimizer)", "optimize_s", true);
  emit("memory", "Peak resident memory of tsah optimize", "bytes per triangle", "bytes_per_triangle", true);
  emit("cost", "Resulting T-SAH cost (one triangle per leaf)", "T-SAH cost", "final_cost", false);
  results["plot_status"] = errors.empty() ? std::to_string(results["plots"].size()) + " plots" : errors.front();
}

}  // namespace tsah::bench
