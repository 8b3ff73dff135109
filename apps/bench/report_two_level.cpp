// The two-level part of results.md (report.hpp): per scene file its table, and one table across scenes.
#include <cstdint>
#include <sstream>

#include "bench/report.hpp"

namespace tsah::bench {

using nlohmann::json;

namespace {

double number(const json& j, const char* key) { return j.contains(key) && j[key].is_number() ? j[key].get<double>() : 0.0; }

bool hasTwoLevel(const json& scene) {
  return scene.is_object() && scene.contains("two_level") && scene["two_level"].contains("methods");
}

const json* methodNamed(const json& part, const std::string& name) {
  for (const json& m : part["methods"])
    if (m.value("name", "") == name) return &m;
  return nullptr;
}

double rate(const json& method) { return number(method["average"]["mrays_per_s"], "total"); }

std::string mib(double bytes) { return formatSignificant(bytes / (1024.0 * 1024.0)); }

// "99.98% (3 of 1,234 rays differ: ...)" of an agreement object (motion_bench.hpp's toJson).
std::string agreementText(const json& a) {
  const json& d = a["differing"];
  return formatFixed(100.0 * number(a, "fraction"), 3) + "% (" +
         std::to_string(uint64_t(number(a, "rays")) - uint64_t(number(a, "same"))) + " of " +
         std::to_string(uint64_t(number(a, "rays"))) + " rays differ: " + std::to_string(uint64_t(number(d, "tie"))) +
         " ties, " + std::to_string(uint64_t(number(d, "one_misses"))) + " one misses, " +
         std::to_string(uint64_t(number(d, "other_depth"))) + " other depth, " +
         std::to_string(uint64_t(number(d, "occlusion"))) + " occlusion)";
}

std::string optimizeText(const json& o) {
  return formatSignificant(number(o, "wall_s")) + " s, " + mib(number(o, "peak_rss_bytes")) + " MiB";
}

// The GPU figures (tsah_two_level_gpu_bench's medians) in one paragraph.
std::string gpuText(const json& g) {
  const json& m = g["median"];
  const json& f = g["flat"]["median"];
  std::ostringstream md;
  md << "GPU (" << g.value("device", "") << ", tsah_two_level_gpu_bench: its own rays, one primary per pixel and "
     << number(g, "ao_per_hit") << " AO per hit; medians): two-level update " << formatSignificant(number(m, "update_ms"))
     << " ms (BLAS refits " << formatSignificant(number(m, "blas_refit_ms")) << ", TLAS "
     << formatSignificant(number(m, "tlas_update_ms")) << "), primary + AO "
     << formatSignificant(number(m, "primary_ms") + number(m, "ao_ms")) << " ms; flat update "
     << formatSignificant(number(f, "update_ms")) << " ms, primary + AO "
     << formatSignificant(number(f, "primary_ms") + number(f, "ao_ms")) << " ms; trace rate two-level / flat "
     << formatFixed(number(g["flat"], "trace_rate_two_level_over_flat"), 2) << "; host TLAS rebuild "
     << formatSignificant(number(m, "tlas_rebuild_cpu_ms")) << " ms per frame.\n\n";
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
  md << "**Two-level part** (" << number(p, "instances") << " instances of " << number(p, "sources") << " sources ("
     << number(p, "static_sources") << " static), " << number(p, "poses") << " poses; " << number(p, "frames")
     << " scene frames at " << number(p, "width") << "x" << number(p, "height") << ", 1 primary + "
     << number(p, "ao_rays") << " AO + " << number(p, "shadow_rays") << " shadow rays per pixel, the same rays for "
     << "every tracer; " << p.value("layout", "") << ", " << number(p, "threads") << " threads; Embree "
     << p.value("embree_status", "") << ")\n\n";
  const json& o = p["optimize"];
  md << "Optimize (`tsah optimize`, wall time and peak resident memory): flat " << optimizeText(o["flat"])
     << "; two-level " << optimizeText(o["two_level"]);
  if (p.contains("embree_build"))
    md << "; Embree instancing built in " << formatSignificant(number(p["embree_build"], "ms")) << " ms ("
       << number(p["embree_build"], "object_scenes") << " scenes below the top level)";
  md << ".\n\n| method | update [ms] | trace [MRays/s] | total [ms] | primary / AO / shadow [MRays/s] | same result as flat |\n"
     << "|---|--:|--:|--:|--:|---|\n";
  for (const json& m : p["methods"]) {
    const json& a = m["average"];
    const json& r = a["mrays_per_s"];
    md << "| " << m.value("label", "") << " | " << formatSignificant(number(a, "update_ms")) << " | "
       << formatSignificant(rate(m)) << " | " << formatSignificant(number(a, "total_ms")) << " | "
       << formatSignificant(number(r, "primary")) << " / " << formatSignificant(number(r, "ao")) << " / "
       << formatSignificant(number(r, "shadow")) << " | ";
    md << (m.contains("extra") && m["extra"].contains("agreement_with_flat")
               ? agreementText(m["extra"]["agreement_with_flat"])
               : "—")
       << " |\n";
  }
  const json& q = p["ratios"];
  md << "\nTwo-level trace rate / flat's: " << formatFixed(number(q, "two_level_rate_over_flat_rate"), 2)
     << "; two-level frame total / flat's: " << formatFixed(number(q, "two_level_total_over_flat_total"), 2);
  if (q.contains("two_level_total_over_embree_total"))
    md << "; two-level frame total / Embree instancing's: "
       << formatFixed(number(q, "two_level_total_over_embree_total"), 2);
  md << ". The per-frame TLAS rebuild (host sweep SAH over the instance boxes, the reference of the refit) is in "
        "`two_level.methods[1].extra.tlas_rebuild_ms_per_frame`.\n\n";
  if (p.contains("gpu")) md << gpuText(p["gpu"]);
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
    auto avg = [](const json* m, const char* key) { return m ? formatSignificant(number((*m)["average"], key)) : ""; };
    const json& q = p["ratios"];
    md << "| " << s.value("name", "") << " | " << number(p, "instances") << " | " << optimizeText(p["optimize"]["flat"])
       << " | " << optimizeText(p["optimize"]["two_level"]) << " | " << avg(flat, "total_ms") << " | "
       << avg(two, "update_ms") << " | " << avg(two, "total_ms") << " | " << avg(embree, "update_ms") << " | "
       << avg(embree, "total_ms") << " | " << formatFixed(number(q, "two_level_rate_over_flat_rate"), 2) << " | "
       << (q.contains("two_level_total_over_embree_total")
               ? formatFixed(number(q, "two_level_total_over_embree_total"), 2)
               : "")
       << " |\n";
  }
  md << "\n(optimize: wall time and peak resident memory of `tsah optimize`; total: update + trace per frame; "
        "total two-level / Embree below 1: the two-level runtime's frame is faster)\n\n";
  return md.str();
}

}  // namespace tsah::bench
