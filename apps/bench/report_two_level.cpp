// The two-level part of results.md (report.hpp): per scene file its table, and one table across scenes.
#include <cstdint>
#include <sstream>

#include "bench/report.hpp"

namespace tsah::bench {

using nlohmann::json;

namespace {

bool hasTwoLevel(const json& scene) {
  return scene.is_object() && scene.contains("two_level") && scene["two_level"].contains("methods");
}

std::string mib(double bytes) { return formatSignificant(bytes / (1024.0 * 1024.0)); }

std::string optimizeText(const json& o) {
  return formatSignificant(numberField(o, "wall_s")) + " s, " + mib(numberField(o, "peak_rss_bytes")) + " MiB";
}

// The GPU TLAS updates compared on the same rays (tsah_two_level_gpu_bench's "tlas": the refit of the
// T-SAH TLAS first, then the per-frame rebuilds), as one sentence; empty without a rebuild.
std::string gpuTlasText(const json& g) {
  if (!g.contains("tlas") || !g["tlas"].is_array() || g["tlas"].size() < 2) return {};
  std::ostringstream md;
  md << " GPU frame total (update + primary + AO, medians) with the TLAS";
  const char* separator = " ";
  for (const json& r : g["tlas"]) {
    const std::string update = r.value("update", "");
    const json& m = r["median"];
    md << separator << (update == "refit" ? "refitted" : "rebuilt by " + update) << " "
       << formatSignificant(numberField(m, "frame_ms")) << " ms (TLAS " << formatSignificant(numberField(m, "tlas_update_ms"))
       << " ms, trace " << formatSignificant(numberField(m, "primary_ms") + numberField(m, "ao_ms")) << " ms";
    if (update != "refit")
      md << ", primary hits unlike the refit's " << uint64_t(numberField(r, "primary_hits_unlike_refit"));
    md << ")";
    separator = ", ";
  }
  md << ".";
  return md.str();
}

// The medians of one tsah_two_level_gpu_bench run: the two-level update and trace, the flat tree's,
// and the trace rate of one over the other.
std::string gpuMediansText(const json& g) {
  const json& m = g["median"];
  const json& f = g["flat"]["median"];
  std::ostringstream md;
  md << "two-level update " << formatSignificant(numberField(m, "update_ms")) << " ms (BLAS refits "
     << formatSignificant(numberField(m, "blas_refit_ms")) << ", TLAS " << formatSignificant(numberField(m, "tlas_update_ms"))
     << "), primary + AO " << formatSignificant(numberField(m, "primary_ms") + numberField(m, "ao_ms"))
     << " ms; flat update " << formatSignificant(numberField(f, "update_ms")) << " ms, primary + AO "
     << formatSignificant(numberField(f, "primary_ms") + numberField(f, "ao_ms")) << " ms; trace rate two-level / flat "
     << formatFixed(numberField(g["flat"], "trace_rate_two_level_over_flat"), 2);
  return md.str();
}

// The GPU figures (tsah_two_level_gpu_bench's medians) in one paragraph: the binary layout's run
// (`gpu`), then the compressed layout's (`gpu_cwbvh`) when there is one.
std::string gpuText(const json& g, const json* compressed) {
  std::ostringstream md;
  md << "GPU (" << g.value("device", "") << ", tsah_two_level_gpu_bench: its own rays, one primary per pixel and "
     << numberField(g, "ao_per_hit") << " AO per hit; medians): " << gpuMediansText(g) << "; host TLAS rebuild "
     << formatSignificant(numberField(g["median"], "tlas_rebuild_cpu_ms")) << " ms per frame.";
  md << gpuTlasText(g);
  if (compressed) md << " BLAS and flat tree in the compressed layout (cwbvh): " << gpuMediansText(*compressed) << ".";
  md << "\n\n";
  return md.str();
}

}  // namespace

std::string twoLevelSection(const json& scene) {
  if (!scene.is_object() || !scene.contains("two_level")) return {};
  const json& p = scene["two_level"];
  std::ostringstream md;
  if (p.contains("skipped")) {
    md << "**Two-level part:** skipped (" << p.value("skipped", "") << ").\n\n";
    return md.str();
  }
  if (!hasTwoLevel(scene)) return {};
  md << "**Two-level part** (" << numberField(p, "instances") << " instances of " << numberField(p, "sources") << " sources ("
     << numberField(p, "static_sources") << " static), " << numberField(p, "poses") << " poses";
  if (p.contains("tlas_trees")) md << ", " << numberField(p, "tlas_trees") << " TLAS tree(s) over the scene's time";
  md << "; " << numberField(p, "frames")
     << " scene frames at " << numberField(p, "width") << "x" << numberField(p, "height") << ", 1 primary + "
     << numberField(p, "ao_rays") << " AO + " << numberField(p, "shadow_rays") << " shadow rays per pixel, the same rays for "
     << "every tracer; " << p.value("layout", "") << ", " << numberField(p, "threads") << " threads; Embree "
     << p.value("embree_status", "") << ")\n\n";
  const json& o = p["optimize"];
  md << "Optimize (`tsah optimize`, wall time and peak resident memory): flat " << optimizeText(o["flat"])
     << "; two-level " << optimizeText(o["two_level"]);
  if (p.contains("embree_build"))
    md << "; Embree instancing built in " << formatSignificant(numberField(p["embree_build"], "ms")) << " ms ("
       << numberField(p["embree_build"], "object_scenes") << " scenes below the top level)";
  md << ".\n\n| method | update [ms] | trace [MRays/s] | total [ms] | primary / AO / shadow [MRays/s] | same result as flat |\n"
     << "|---|--:|--:|--:|--:|---|\n";
  for (const json& m : p["methods"]) {
    const json& a = m["average"];
    const json& r = a["mrays_per_s"];
    md << "| " << m.value("label", "") << " | " << formatSignificant(numberField(a, "update_ms")) << " | "
       << formatSignificant(averageRate(m)) << " | " << formatSignificant(numberField(a, "total_ms")) << " | "
       << formatSignificant(numberField(r, "primary")) << " / " << formatSignificant(numberField(r, "ao")) << " / "
       << formatSignificant(numberField(r, "shadow")) << " | ";
    md << (m.contains("extra") && m["extra"].contains("agreement_with_flat")
               ? agreementText(m["extra"]["agreement_with_flat"], true)
               : "—")
       << " |\n";
  }
  const json& q = p["ratios"];
  md << "\nTwo-level trace rate / flat's: " << formatFixed(numberField(q, "two_level_rate_over_flat_rate"), 2)
     << "; two-level frame total / flat's: " << formatFixed(numberField(q, "two_level_total_over_flat_total"), 2);
  if (q.contains("two_level_total_over_embree_total"))
    md << "; two-level frame total / Embree instancing's: "
       << formatFixed(numberField(q, "two_level_total_over_embree_total"), 2);
  md << ". The per-frame TLAS rebuild (host sweep SAH over the instance boxes, the reference of the refit) is in "
        "`two_level.methods[1].extra.tlas_rebuild_ms_per_frame`.\n\n";
  if (p.contains("gpu")) md << gpuText(p["gpu"], p.contains("gpu_cwbvh") ? &p["gpu_cwbvh"] : nullptr);
  return md.str();
}

std::string twoLevelSummary(const json& scenes) {
  bool any = false;
  for (const json& s : scenes) any = any || hasTwoLevel(s);
  if (!any) return {};
  std::ostringstream md;
  md << "## Two-level scenes: flat, two-level and Embree instancing\n\n"
     << "| scene | instances | optimize flat | optimize two-level | flat total [ms] | two-level update [ms] | "
        "two-level total [ms] | Embree update [ms] | Embree total [ms] | rate two-level / flat | total two-level / "
        "Embree |\n"
     << "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|\n";
  for (const json& s : scenes) {
    if (!hasTwoLevel(s)) continue;
    const json& p = s["two_level"];
    const json* flat = methodNamed(p, "flat");
    const json* two = methodNamed(p, "two-level");
    const json* embree = methodNamed(p, "embree-instanced");
    auto avg = [](const json* m, const char* key) { return m ? formatSignificant(numberField((*m)["average"], key)) : ""; };
    const json& q = p["ratios"];
    md << "| " << s.value("name", "") << " | " << numberField(p, "instances") << " | " << optimizeText(p["optimize"]["flat"])
       << " | " << optimizeText(p["optimize"]["two_level"]) << " | " << avg(flat, "total_ms") << " | "
       << avg(two, "update_ms") << " | " << avg(two, "total_ms") << " | " << avg(embree, "update_ms") << " | "
       << avg(embree, "total_ms") << " | " << formatFixed(numberField(q, "two_level_rate_over_flat_rate"), 2) << " | "
       << (q.contains("two_level_total_over_embree_total")
               ? formatFixed(numberField(q, "two_level_total_over_embree_total"), 2)
               : "")
       << " |\n";
  }
  md << "\n(optimize: wall time and peak resident memory of `tsah optimize`; total: update + trace per frame; "
        "total two-level / Embree below 1: the two-level runtime's frame is faster)\n\n";
  return md.str();
}

}  // namespace tsah::bench
