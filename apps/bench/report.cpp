#include "bench/report.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

#include "tsah/base/error.hpp"
#include "bench/plot.hpp"
#include "bench/process.hpp"

namespace tsah::bench {

namespace fs = std::filesystem;
using nlohmann::json;

std::string formatFixed(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

std::string formatSignificant(double value) {
  const double a = std::fabs(value);
  if (a == 0.0) return "0";
  if (a >= 100.0) return formatFixed(value, 0);
  if (a >= 10.0) return formatFixed(value, 1);
  if (a >= 1.0) return formatFixed(value, 2);
  if (a >= 0.1) return formatFixed(value, 3);
  return formatFixed(value, 4);
}

double numberField(const json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : 0.0;
}

const json* methodNamed(const json& part, const std::string& name) {
  for (const json& m : part["methods"])
    if (m.value("name", "") == name) return &m;
  return nullptr;
}

double averageRate(const json& method) { return numberField(method["average"]["mrays_per_s"], "total"); }

std::string agreementText(const json& agreement, bool details) {
  std::string s = formatFixed(100.0 * numberField(agreement, "fraction"), 3) + "%";
  if (!details) return s;
  const json& d = agreement["differing"];
  const auto count = [](const json& j, const char* key) { return std::to_string(uint64_t(numberField(j, key))); };
  return s + " (" + std::to_string(uint64_t(numberField(agreement, "rays")) - uint64_t(numberField(agreement, "same"))) +
         " of " + count(agreement, "rays") + " rays differ: " + count(d, "tie") + " ties, " + count(d, "one_misses") +
         " one misses, " + count(d, "other_depth") + " other depth, " + count(d, "occlusion") + " occlusion)";
}

namespace {

std::string withThousands(uint64_t n) {
  std::string digits = std::to_string(n), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

double num(const json& j, const char* key, double fallback = 0.0) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : fallback;
}
std::string str(const json& j, const char* key, const std::string& fallback = {}) {
  return j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : fallback;
}

// The segments experiment ran with K > 1 trees (--segments 1 with a budget records only the one
// tree and the budget mode). A const json's operator[] must only see keys that exist.
bool hasKTrees(const json& scene) {
  return scene.contains("segments") && scene["segments"].is_object() && scene["segments"].contains("k_trees") &&
         scene["segments"]["k_trees"].is_object();
}

const json* findByKey(const json& array, const char* key, const std::string& value) {
  if (!array.is_array()) return nullptr;
  for (const json& e : array)
    if (e.is_object() && str(e, key) == value) return &e;
  return nullptr;
}

// The paper's figures for a scene, when results.json holds them and they are for the same scene.
const json* samePaperScene(const json& scene) {
  if (!scene.contains("paper") || !scene["paper"].is_object()) return nullptr;
  return scene["paper"].value("same_scene", false) ? &scene["paper"] : nullptr;
}

std::string deviceName(const json& results) {
  const json& m = results.value("machine", json::object());
  if (m.contains("gpu") && m["gpu"].is_object()) return str(m["gpu"], "name", "GPU");
  return "CPU";
}

std::string rays3(const json& average) {
  const json& r = average.value("mrays_per_s", json::object());
  return formatSignificant(num(r, "primary")) + " / " + formatSignificant(num(r, "ao")) + " / " +
         formatSignificant(num(r, "shadow"));
}

double totalRate(const json& method) { return num(method["average"]["mrays_per_s"], "total"); }

void machineSection(std::ostringstream& md, const json& results) {
  const json& m = results.value("machine", json::object());
  const json& v = results.value("versions", json::object());
  const json& o = results.value("options", json::object());
  md << "**Machine:** " << str(m, "cpu", "unknown CPU") << ", " << num(m, "logical_cores") << " logical cores";
  if (m.contains("memory_gib")) md << ", " << formatFixed(num(m, "memory_gib"), 1) << " GiB";
  if (!str(m, "os").empty()) md << ", " << str(m, "os");
  md << ".";
  if (m.contains("gpu") && m["gpu"].is_object()) {
    const json& g = m["gpu"];
    md << " **GPU:** " << str(g, "name") << " (" << formatFixed(num(g, "memory_mib") / 1024.0, 0) << " GiB, compute "
       << str(g, "compute_capability") << ", CUDA driver " << int(num(g, "driver_version")) / 1000 << "."
       << (int(num(g, "driver_version")) % 1000) / 10 << ", runtime " << int(num(g, "runtime_version")) / 1000 << "."
       << (int(num(g, "runtime_version")) % 1000) / 10 << ").";
  }
  const std::string embree = str(v, "embree");
  md << "\n\n**Build:** tsah " << str(v, "tsah") << ", " << str(v, "compiler") << ", " << str(v, "build") << "; "
     << (!embree.empty() && std::isdigit(static_cast<unsigned char>(embree[0])) ? "Embree " + embree : embree) << ".\n\n";
  md << "**Settings:** " << num(o, "frames") << " representative frames, " << num(o, "eval_frames")
     << " evaluation frames (Table 1); runtime " << num(o, "trace_frames") << " frames per method at "
     << num(o, "width") << "×" << num(o, "height") << ", 1 primary + " << num(o, "ao_rays") << " AO + "
     << num(o, "shadow_rays") << " shadow rays per pixel, "
     << (o.value("ground", false) ? "with the ground plane" : "mesh only (no ground plane, as in the paper)")
     << "; leaves of at most " << num(o, "max_leaf") << " triangles; cT = " << num(o, "ct") << ", cI = " << num(o, "ci")
     << "; seed " << num(o, "seed") << "; " << (num(o, "threads") > 0 ? std::to_string(int(num(o, "threads"))) : "all")
     << " CPU threads; device " << str(o, "device") << (o.value("quick", false) ? "; **--quick** (a smoke run)" : "")
     << ".\n\n";
}

void table1Section(std::ostringstream& md, const json& scene) {
  if (!scene.contains("table1")) return;
  const json& t1 = scene["table1"];
  const json* paper = samePaperScene(scene);
  md << "**Table 1** (tree quality: Eq. 1 cost over " << num(t1, "eval_frames")
     << " evaluation frames; build = CPU seconds on one core";
  if (paper) md << "; paper: " << str(*paper, "paper_name") << ", its Table 1";
  md << ")\n\n| method | build [s] | cost | max cost |";
  if (paper) md << " paper build [s] | paper cost | paper max |";
  md << "\n|---|--:|--:|--:|" << (paper ? "--:|--:|--:|" : "") << "\n";
  for (const json& m : t1["methods"]) {
    md << "| " << str(m, "label") << " | " << formatFixed(num(m, "build_s"), 2) << " | "
       << formatFixed(num(m, "average"), 2) << " | " << formatFixed(num(m, "maximum"), 2) << " |";
    if (paper) {
      if (const json* p = findByKey((*paper)["table1"], "method", str(m, "name")))
        md << " " << formatSignificant(num(*p, "build_s")) << " | " << num(*p, "average") << " | " << num(*p, "maximum")
           << " |";
      else
        md << " | | |";
    }
    md << "\n";
  }
  md << "\n";
}

void table2Section(std::ostringstream& md, const json& scene, const std::string& device) {
  if (!scene.contains("runtime")) return;
  const json& rt = scene["runtime"];
  const json* paper = samePaperScene(scene);
  const bool gpu = str(rt, "device") == "cuda";
  md << "**Table 2** (runtime on the " << (gpu ? device : "CPU")
     << (rt.contains("layout") ? ", " + str(rt, "layout") + " layout" : std::string()) << ": " << num(rt, "frames")
     << " frames, "
     << num(rt, "width") << "×" << num(rt, "height") << ", " << str(rt, "camera")
     << "; update = interpolation + refit + Woop, or + rebuild"
     << (gpu && rt.contains("layout") && str(rt, "layout") == "cwbvh" ? " + conversion to the wide layout" : "")
     << "; trace speed over all rays; total = update + trace";
  if (gpu) md << " + the rest of the frame on the device";
  if (paper) md << "; paper: GTX TITAN Black, its Table 2";
  md << ")\n\n| method | update [ms] | trace [MRays/s] | total [ms] | primary / AO / shadow [MRays/s] | rays per frame |";
  if (paper) md << " paper update [ms] | paper MRays/s | paper total [ms] |";
  md << "\n|---|--:|--:|--:|--:|--:|" << (paper ? "--:|--:|--:|" : "") << "\n";
  for (const json& m : rt["methods"]) {
    const json& a = m["average"];
    md << "| " << str(m, "label") << " | " << formatSignificant(num(a, "update_ms")) << " | "
       << formatSignificant(totalRate(m)) << " | " << formatSignificant(num(a, "total_ms")) << " | " << rays3(a) << " | "
       << withThousands(uint64_t(std::llround(num(a["rays_per_frame"], "total")))) << " |";
    if (paper) {
      if (const json* p = findByKey((*paper)["table2"], "method", str(m, "name")))
        md << " " << num(*p, "update_ms") << " | " << num(*p, "mrays_per_s") << " | " << num(*p, "total_ms") << " |";
      else
        md << " | | |";
    }
    md << "\n";
  }
  if (paper) {
    // The paper's per-frame SAH-rebuild (precomputed trees, update 0) has no runtime row here.
    if (const json* p = findByKey((*paper)["table2"], "method", "rebuild"))
      md << "| *paper only:* SAH-rebuild (a precomputed tree per frame) | | | | | | " << num(*p, "update_ms") << " | "
         << num(*p, "mrays_per_s") << " | " << num(*p, "total_ms") << " |\n";
    if (!gpu)
      for (const char* id : {"lbvh", "hlbvh-sah"})
        if (const json* p = findByKey((*paper)["table2"], "method", id))
          md << "| *paper only:* " << (std::string(id) == "lbvh" ? "HLBVH-med" : "HLBVH-SAH") << " (GPU rebuild) | | | | | | "
             << num(*p, "update_ms") << " | " << num(*p, "mrays_per_s") << " | " << num(*p, "total_ms") << " |\n";
  }
  md << "\n";
}

const json* runtimeMethod(const json& scene, const std::string& name) {
  if (!scene.contains("runtime")) return nullptr;
  return findByKey(scene["runtime"]["methods"], "name", name);
}

void segmentsSection(std::ostringstream& md, const json& scene) {
  if (!scene.contains("segments")) return;
  const json& s = scene["segments"];
  const int k = int(num(s, "count"));
  const json* one = runtimeMethod(scene, "tsah0");
  const json* many = runtimeMethod(scene, "tsah0-seg" + std::to_string(k));
  md << "**Segments** (T-SAH k=0: one tree for the whole animation vs " << k
     << " trees for equal-time parts or with split points chosen by the count mode, and the budget mode's "
        "fewest trees; every frame refits the tree of its part)\n\n"
     << "| trees | build [s] | cost | max cost | update [ms] | trace [MRays/s] | total [ms] |\n"
     << "|---|--:|--:|--:|--:|--:|--:|\n";
  auto row = [&](const std::string& label, const json& cost, double build, const json* rt) {
    md << "| " << label << " | " << formatFixed(build, 2) << " | " << formatFixed(num(cost, "average"), 2) << " | "
       << formatFixed(num(cost, "maximum"), 2) << " | ";
    if (rt)
      md << formatSignificant(num((*rt)["average"], "update_ms")) << " | " << formatSignificant(totalRate(*rt)) << " | "
         << formatSignificant(num((*rt)["average"], "total_ms")) << " |\n";
    else
      md << " | | |\n";
  };
  row("1", s["one_tree"], num(s["one_tree"], "build_s"), one);
  if (s.contains("k_trees")) row(std::to_string(k) + ", equal time", s["k_trees"], num(s, "build_s"), many);
  if (s.contains("count_mode"))
    row(std::to_string(k) + ", count mode", s["count_mode"], num(s["count_mode"], "build_s"),
        runtimeMethod(scene, "tsah0-count" + std::to_string(k)));
  if (s.contains("budget_mode")) {
    const json& b = s["budget_mode"];
    row(std::to_string(int(num(b, "trees"))) + ", budget " + formatSignificant(num(b, "budget")) + "x", b,
        num(b, "build_s"), runtimeMethod(scene, "tsah0-budget"));
  }
  md << "\n(build: one tree = CPU seconds of the optimizing thread; sets = wall seconds of their trees' builds";
  for (const char* mode : {"count_mode", "budget_mode"})
    if (s.contains(mode)) {
      const json& m = s[mode];
      md << "; " << (std::string(mode) == "count_mode" ? "count" : "budget") << " mode: split times";
      for (const json& t : m["split_times"]) md << " " << formatSignificant(t.get<double>());
      md << ", search " << formatFixed(num(m, "search_s"), 1) << " s over " << int(num(m, "candidate_trees"))
         << " candidate trees";
      if (m.contains("peak_ratio_to_rebuild"))
        md << ", peak/average cost ratio to SAH-rebuild " << formatFixed(num(m, "peak_ratio_to_rebuild"), 3) << " / "
           << formatFixed(num(m, "average_ratio_to_rebuild"), 3);
    }
  md << ")\n\n";
}

// Toolkit vs Embree: where each wins, in one paragraph of facts. The toolkit is the first method
// (its default layout); the peers are the embree-* methods.
std::string embreeVerdict(const json& methods) {
  if (!methods.is_array() || methods.size() < 2) return {};
  const json& own = methods[0];
  const json* fastest = nullptr;
  const json* quickest = nullptr;
  for (std::size_t i = 1; i < methods.size(); ++i) {
    if (str(methods[i], "name").rfind("embree", 0) != 0) continue;  // another toolkit layout
    if (!fastest || totalRate(methods[i]) > totalRate(*fastest)) fastest = &methods[i];
    if (!quickest || num(methods[i]["average"], "total_ms") < num((*quickest)["average"], "total_ms"))
      quickest = &methods[i];
  }
  if (!fastest) return {};
  const double ownRate = totalRate(own), peerRate = totalRate(*fastest);
  const double ownTotal = num(own["average"], "total_ms"), peerTotal = num((*quickest)["average"], "total_ms");
  const json* refit = findByKey(methods, "name", "embree-refit");
  std::ostringstream s;
  if (peerRate > ownRate)
    s << "Trace speed: " << str(*fastest, "label") << " wins, " << formatFixed(peerRate / ownRate, 2) << "× the toolkit's ("
      << formatSignificant(peerRate) << " vs " << formatSignificant(ownRate) << " MRays/s). ";
  else
    s << "Trace speed: the toolkit wins, " << formatFixed(ownRate / peerRate, 2) << "× the fastest Embree variant, "
      << str(*fastest, "label") << " (" << formatSignificant(ownRate) << " vs " << formatSignificant(peerRate)
      << " MRays/s). ";
  if (refit) {
    const double a = num(own["average"], "update_ms"), b = num((*refit)["average"], "update_ms");
    s << "Update: the toolkit's refit takes " << formatSignificant(a) << " ms, Embree's refit " << formatSignificant(b)
      << " ms (" << (a <= b ? "toolkit" : "Embree") << " wins). ";
  }
  if (peerTotal < ownTotal)
    s << "Total frame time: " << str(*quickest, "label") << " wins (" << formatSignificant(peerTotal) << " vs "
      << formatSignificant(ownTotal) << " ms, the toolkit " << formatFixed(100.0 * (ownTotal / peerTotal - 1.0), 0)
      << "% slower).";
  else
    s << "Total frame time: the toolkit wins (" << formatSignificant(ownTotal) << " vs " << formatSignificant(peerTotal)
      << " ms for " << str(*quickest, "label") << ", " << formatFixed(100.0 * (peerTotal / ownTotal - 1.0), 0)
      << "% slower).";
  for (const json& m : methods)  // the toolkit's tree set, when traced
    if (m.contains("extra") && m["extra"].contains("trees") && refit) {
      const double set = num(m["average"], "total_ms"), peer = num((*refit)["average"], "total_ms");
      s << " With " << m["extra"]["trees"].get<int>() << " trees (" << str(m, "label") << ") a frame takes "
        << formatSignificant(set) << " ms, Embree refit " << formatSignificant(peer) << " ms ("
        << formatFixed(peer / set, 2) << "× the toolkit's).";
    }
  return s.str();
}

void embreeSection(std::ostringstream& md, const json& scene) {
  if (!scene.contains("embree")) return;
  const json& e = scene["embree"];
  if (!e.contains("methods")) {
    if (e.contains("skipped")) return;
    md << "**CPU peer:** " << str(e, "status") << "\n\n";
    return;
  }
  md << "**CPU peer: Embree " << str(e, "status") << "** (the same " << num(e, "frames")
     << " frames and the same rays — made once per frame from the toolkit's primary hits — traced by both; "
        "rtcIntersect1/rtcOccluded1 on the same threads; update includes the interpolation)\n\n"
     << "| method | update [ms] | trace [MRays/s] | total [ms] | primary / AO / shadow [MRays/s] | results differing from the toolkit (primary hits / AO / shadow occlusions, all frames) |\n"
     << "|---|--:|--:|--:|--:|--:|\n";
  for (const json& m : e["methods"]) {
    const json& a = m["average"];
    md << "| " << str(m, "label") << " | " << formatSignificant(num(a, "update_ms")) << " | "
       << formatSignificant(totalRate(m)) << " | " << formatSignificant(num(a, "total_ms")) << " | " << rays3(a) << " | ";
    if (m.contains("extra") && m["extra"].contains("hits_minus_toolkit")) {
      const json& d = m["extra"]["hits_minus_toolkit"];
      md << d.value("primary", 0) << " / " << d.value("ao_occluded", 0) << " / " << d.value("shadow_occluded", 0);
    } else {
      md << "—";
    }
    md << " |\n";
  }
  md << "\n" << embreeVerdict(e["methods"]) << "\n\n";
}

void plotsSection(std::ostringstream& md, const json& results, const json& scene) {
  if (!results.contains("plots") || !results["plots"].contains("files")) return;
  const std::string name = str(scene, "name");
  const std::vector<std::pair<std::string, std::string>> plots = {
      {"cost", "cost per evaluation frame (paper Figure 4 left)"},
      {"convergence", "optimization convergence by node selection (paper Figure 3)"},
      {"total", "total frame time per frame (paper Figure 5)"},
      {"speed", "trace speed per frame (paper Figure 6)"},
      {"embree", "toolkit vs Embree per frame"}};
  bool any = false;
  for (const auto& [suffix, caption] : plots) {
    const std::string file = "plots/" + name + "-" + suffix + ".png";
    for (const json& f : results["plots"]["files"])
      if (f.is_string() && f.get<std::string>() == file) {
        md << (any ? " " : "") << "[" << caption << "](" << file << ")";
        any = true;
      }
  }
  if (any) md << "\n\n";
}

}  // namespace

std::string renderMarkdown(const json& results) {
  std::ostringstream md;
  md << "# tsah bench: results\n\n";
  md << "Generated by `tsah bench` from `results.json`";
  if (results.contains("finished")) md << ", run finished " << str(results, "finished");
  md << ". Command:\n\n    " << str(results, "command") << "\n\n";
  machineSection(md, results);
  if (results.contains("notes") && !results["notes"].empty()) {
    md << "**Notes:**\n\n";
    for (const json& n : results["notes"]) md << "- " << n.get<std::string>() << "\n";
    md << "\n";
  }
  const json& scenes = results.value("scenes", json::array());
  md << "**Scenes** (" << scenes.size() << "):\n\n| scene | triangles | keyframes | kind | from | wall time [s] |\n"
     << "|---|--:|--:|---|---|--:|\n";
  for (const json& s : scenes)
    md << "| [" << str(s, "name") << "](#" << str(s, "name") << ") | " << withThousands(uint64_t(num(s, "triangles")))
       << " | " << num(s, "keyframes") << " | " << str(s, "kind") << " | " << str(s, "origin") << " | "
       << formatFixed(num(s, "wall_s"), 0) << " |\n";
  md << "\n";
  for (const char* list : {"failed", "skipped"})
    if (results.contains(list) && !results[list].empty()) {
      md << (std::string(list) == "failed" ? "**Failed:** " : "**Not benchmarked:** ");
      bool first = true;
      for (const json& f : results[list]) {
        md << (first ? "" : "; ") << "`" << str(f, "path") << "` (" << str(f, "reason") << ")";
        first = false;
      }
      md << ".\n\n";
    }
  if (results.contains("plots")) md << "**Plots:** " << str(results["plots"], "status") << ".\n\n";

  const std::string device = deviceName(results);
  for (const json& s : scenes) {
    md << "## " << str(s, "name") << "\n\n"
       << withThousands(uint64_t(num(s, "triangles"))) << " triangles, " << withThousands(uint64_t(num(s, "vertices")))
       << " vertices, " << num(s, "keyframes") << " keyframes over t = " << formatSignificant(num(s, "time_start"))
       << " … " << formatSignificant(num(s, "time_end")) << " (" << str(s, "kind") << ", `" << str(s, "origin")
       << "`; loaded in " << formatFixed(num(s, "load_s"), 1) << " s).\n\n";
    if (s.contains("image"))
      md << "![" << str(s, "name") << "](" << str(s["image"], "file") << ")\n\n";
    table1Section(md, s);
    table2Section(md, s, device);
    segmentsSection(md, s);
    embreeSection(md, s);
    md << motionBlurSection(s);
    md << twoLevelSection(s);
    plotsSection(md, results, s);
  }

  // Across scenes: segmenting and the Embree verdicts.
  bool anySegments = false;
  for (const json& s : scenes) anySegments = anySegments || hasKTrees(s);
  if (anySegments) {
    md << "## Segmenting: one tree vs K trees (the paper's BART Museum*)\n\n"
       << "| scene | K | cost (1 tree) | max (1) | cost (K trees) | max (K) | total ms (1 tree) | total ms (K trees) |\n"
       << "|---|--:|--:|--:|--:|--:|--:|--:|\n";
    for (const json& s : scenes) {
      if (!hasKTrees(s)) continue;
      const json& g = s["segments"];
      const int k = int(num(g, "count"));
      const json* one = runtimeMethod(s, "tsah0");
      const json* many = runtimeMethod(s, "tsah0-seg" + std::to_string(k));
      md << "| " << str(s, "name") << " | " << k << " | " << formatFixed(num(g["one_tree"], "average"), 2) << " | "
         << formatFixed(num(g["one_tree"], "maximum"), 2) << " | " << formatFixed(num(g["k_trees"], "average"), 2) << " | "
         << formatFixed(num(g["k_trees"], "maximum"), 2) << " | "
         << (one ? formatSignificant(num((*one)["average"], "total_ms")) : "") << " | "
         << (many ? formatSignificant(num((*many)["average"], "total_ms")) : "") << " |\n";
    }
    md << "\n";
    for (const json& s : scenes) {
      if (!s.contains("paper") || !s["paper"].contains("table2_segmented")) continue;
      const json& p = s["paper"];
      const json* one = findByKey(p["table2"], "method", "tsah0");
      const json* three = findByKey(p["table2_segmented"], "method", "tsah0");
      if (!one || !three) continue;
      md << "For context, the paper's " << str(p, "paper_name") << " (" << withThousands(uint64_t(num(p, "triangles")))
         << " triangles"
         << (p.value("same_scene", true) ? "" : ": another version of the scene than the data's, so not comparable number for number")
         << "): T-SAH with one tree " << num(*one, "mrays_per_s") << " MRays/s and " << num(*one, "total_ms")
         << " ms per frame, with three trees (Museum*) " << num(*three, "mrays_per_s") << " MRays/s and "
         << num(*three, "total_ms") << " ms (its Table 2).\n\n";
    }
  }
  bool anyEmbree = false;
  for (const json& s : scenes) anyEmbree = anyEmbree || (s.contains("embree") && s["embree"].contains("methods"));
  if (anyEmbree) {
    md << "## Toolkit vs Embree: where each wins\n\n";
    for (const json& s : scenes)
      if (s.contains("embree") && s["embree"].contains("methods"))
        md << "- **" << str(s, "name") << "**: " << embreeVerdict(s["embree"]["methods"]) << "\n";
    md << "\n";
  }
  md << motionBlurSummary(scenes);
  md << twoLevelSummary(scenes);
  md << "## Source of the paper's figures\n\n" << str(results, "paper_source") << ".\n";
  return md.str();
}

// ---------------------------------------------------------------------------------------------
// Plots

std::string gnuplotVersion() {
  const ProcessResult r = runProcess({"gnuplot", "--version"});
  if (!r.ok()) return {};
  std::string v = r.output.substr(0, r.output.find('\n'));
  return v;
}

namespace {

std::vector<double> numbers(const json& array) {
  std::vector<double> v;
  if (array.is_array())
    for (const json& x : array) v.push_back(x.is_number() ? x.get<double>() : std::nan(""));
  return v;
}

std::vector<double> indices(std::size_t n) {
  std::vector<double> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = double(i);
  return v;
}

}  // namespace

PlotOutcome makePlots(const json& results, const fs::path& outDir) {
  PlotOutcome out;
  const std::string version = gnuplotVersion();
  if (version.empty()) {
    out.status = "skipped: gnuplot is not installed (install gnuplot-nox, then run tsah bench --report-only " +
                 outDir.string() + ")";
    return out;
  }
  const fs::path dir = outDir / "plots";
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    out.status = "skipped: cannot create " + dir.string();
    return out;
  }
  const bool cairo = cairoAvailable();
  Plotter plotter(dir, plotTerminal(cairo));
  std::vector<std::string> errors;
  for (const json& scene : results.value("scenes", json::array())) {
    const std::string name = str(scene, "name");
    auto emit = [&](const std::string& suffix, const std::string& title, const std::string& xl, const std::string& yl,
                    const std::vector<Series>& series, bool logY) {
      std::string error;
      if (plotter.plot(name + "-" + suffix, name + ": " + title, xl, yl, series, logY, error))
        out.files.push_back("plots/" + name + "-" + suffix + ".png");
      else
        errors.push_back(error);
    };
    if (scene.contains("table1")) {
      std::vector<Series> series;
      for (const json& m : scene["table1"]["methods"]) {
        const std::vector<double> y = numbers(m["per_frame"]);
        series.push_back({str(m, "label"), indices(y.size()), y});
      }
      if (hasKTrees(scene)) {
        const std::vector<double> y = numbers(scene["segments"]["k_trees"]["per_frame"]);
        series.push_back({"T-SAH k=0, " + std::to_string(int(num(scene["segments"], "count"))) + " trees",
                          indices(y.size()), y});
      }
      emit("cost", "BVH cost per evaluation frame (cf. paper Figure 4 left)", "evaluation frame",
           "cost (Eq. 1)", series, false);
    }
    if (scene.contains("convergence") && !scene["convergence"].empty()) {
      std::vector<Series> series;
      for (const json& c : scene["convergence"]) {
        Series s{str(c, "label"), {}, {}};
        for (const json& h : c["history"]) {
          s.x.push_back(num(h, "elapsed_s"));
          s.y.push_back(num(h, "average"));
        }
        series.push_back(s);
      }
      emit("convergence", "T-SAH k=0 optimization by node selection (cf. paper Figure 3)", "optimization time [s]",
           "average cost over the representative frames (one triangle per leaf)", series, false);
    }
    auto runtimeSeries = [&](const json& methods, const char* key) {
      std::vector<Series> series;
      for (const json& m : methods) {
        const std::vector<double> y = numbers(m["per_frame"][key]);
        series.push_back({str(m, "label"), indices(y.size()), y});
      }
      return series;
    };
    if (scene.contains("runtime")) {
      const std::string where = str(scene["runtime"], "device") == "cuda" ? "GPU" : "CPU";
      emit("total", "total frame time, " + where + " (cf. paper Figure 5)", "frame", "total time [ms]",
           runtimeSeries(scene["runtime"]["methods"], "total_ms"), false);
      emit("speed", "trace speed, " + where + " (cf. paper Figure 6)", "frame", "trace speed [MRays/s]",
           runtimeSeries(scene["runtime"]["methods"], "mrays_per_s"), false);
    }
    if (scene.contains("embree") && scene["embree"].contains("methods"))
      emit("embree", "toolkit vs Embree on the same rays", "frame", "total time [ms]",
           runtimeSeries(scene["embree"]["methods"], "total_ms"), false);
  }
  out.made = !out.files.empty();
  out.status = version + (cairo ? " (pngcairo)" : " (png)") + ": " + std::to_string(out.files.size()) + " plots in plots/";
  if (!errors.empty()) out.status += "; failed: " + errors.front() + (errors.size() > 1 ? " and others" : "");
  return out;
}

}  // namespace tsah::bench
