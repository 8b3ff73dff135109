// The motion-blur part of results.md (report.hpp): per scene its table, and one table across scenes.
#include <cstdint>
#include <cstdio>
#include <sstream>

#include "bench/report.hpp"

namespace tsah::bench {

using nlohmann::json;

namespace {

bool hasMotionBlur(const json& scene) {
  return scene.is_object() && scene.contains("motion_blur") && scene["motion_blur"].contains("methods");
}

// The mean of a per-frame count (keys_per_frame, keys_refitted_per_frame); 0 when absent.
double averageKeys(const json& blur, const char* field = "keys_per_frame") {
  double sum = 0.0;
  for (const json& k : blur.value(field, json::array())) sum += k.get<double>();
  const std::size_t n = blur.value(field, json::array()).size();
  return n ? sum / double(n) : 0.0;
}

// "0.5 centered", as the option was given.
std::string shutterText(const json& blur) {
  const json& s = blur["shutter"];
  char fraction[32];
  std::snprintf(fraction, sizeof fraction, "%g", numberField(s, "fraction"));
  return fraction + (" " + s.value("mode", "centered"));
}

}  // namespace

std::string motionBlurSection(const json& scene) {
  if (!hasMotionBlur(scene)) return {};
  const json& blur = scene["motion_blur"];
  std::ostringstream md;
  md << "**Motion blur** (shutter " << shutterText(blur) << " of the time between traced frames, "
     << formatSignificant(numberField(blur, "frame_interval")) << "; " << numberField(blur, "frames")
     << " frames, the same rays at the same times for every tracer — each pixel's rays at its time; the toolkit's "
     << blur.value("layout", "") << " refit at the shutter's keys (" << formatFixed(averageKeys(blur), 1)
     << " keys per frame on average";
  if (blur.contains("keys_refitted_per_frame"))
    md << ", " << formatFixed(averageKeys(blur, "keys_refitted_per_frame"), 1)
       << " refitted, the others reused from the frame before";
  md << "); Embree " << blur.value("embree_status", "")
     << " motion-blur BVH built once over the keyframes";
  if (blur.contains("embree_mb_build"))
    md << " (" << numberField(blur["embree_mb_build"], "time_steps") << " time steps, "
       << formatSignificant(numberField(blur["embree_mb_build"], "ms")) << " ms, not in the frame times)";
  md << " and rebuilt every frame over the shutter's keys)\n\n"
     << "| method | update [ms] | trace [MRays/s] | total [ms] | primary / AO / shadow [MRays/s] | same result as the toolkit |\n"
     << "|---|--:|--:|--:|--:|---|\n";
  for (const json& m : blur["methods"]) {
    const json& a = m["average"];
    const json& r = a["mrays_per_s"];
    md << "| " << m.value("label", "") << " | " << formatSignificant(numberField(a, "update_ms")) << " | "
       << formatSignificant(averageRate(m)) << " | " << formatSignificant(numberField(a, "total_ms")) << " | "
       << formatSignificant(numberField(r, "primary")) << " / " << formatSignificant(numberField(r, "ao")) << " / "
       << formatSignificant(numberField(r, "shadow")) << " | ";
    md << (m.contains("extra") && m["extra"].contains("agreement") ? agreementText(m["extra"]["agreement"], true) : "—")
       << " |\n";
  }
  if (blur.contains("ratios")) {
    const json& q = blur["ratios"];
    md << "\nToolkit trace rate / Embree motion-blur BVH's: "
       << formatFixed(numberField(q, "toolkit_rate_over_embree_mb_rate"), 2)
       << "; toolkit frame total / Embree per-frame rebuild's: "
       << formatFixed(numberField(q, "toolkit_total_over_embree_rebuild_total"), 2)
       << ". Differing rays: a tie is another triangle at the same t within 1e-4 relative (the traversal order "
          "decides); one misses and other depth are rays grazing an edge, where the two watertight tests round "
          "differently; occlusion counts AO and shadow rays one finds blocked and the other not.\n";
  }
  md << "\n";
  return md.str();
}

std::string motionBlurSummary(const json& scenes) {
  bool any = false;
  for (const json& s : scenes) any = any || hasMotionBlur(s);
  if (!any) return {};
  std::ostringstream md;
  md << "## Motion blur: the toolkit against Embree\n\n"
     << "| scene | shutter | keys per frame | toolkit update [ms] | toolkit trace [MRays/s] | toolkit total [ms] | "
        "Embree MB [MRays/s] | Embree MB build once [ms] | Embree rebuild total [ms] | trace rate ratio | frame total "
        "ratio | agreement (MB / rebuild) |\n"
     << "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|\n";
  for (const json& s : scenes) {
    if (!hasMotionBlur(s)) continue;
    const json& blur = s["motion_blur"];
    const json* own = methodNamed(blur, "tsah0-mb");
    const json* once = methodNamed(blur, "embree-mb");
    const json* rebuild = methodNamed(blur, "embree-mb-rebuild");
    md << "| " << s.value("name", "") << " | " << shutterText(blur) << " | " << formatFixed(averageKeys(blur), 1) << " | ";
    if (own)
      md << formatSignificant(numberField((*own)["average"], "update_ms")) << " | " << formatSignificant(averageRate(*own)) << " | "
         << formatSignificant(numberField((*own)["average"], "total_ms")) << " | ";
    else
      md << " | | | ";
    md << (once ? formatSignificant(averageRate(*once)) : "") << " | "
       << (blur.contains("embree_mb_build") ? formatSignificant(numberField(blur["embree_mb_build"], "ms")) : "") << " | "
       << (rebuild ? formatSignificant(numberField((*rebuild)["average"], "total_ms")) : "") << " | ";
    if (blur.contains("ratios"))
      md << formatFixed(numberField(blur["ratios"], "toolkit_rate_over_embree_mb_rate"), 2) << " | "
         << formatFixed(numberField(blur["ratios"], "toolkit_total_over_embree_rebuild_total"), 2) << " | ";
    else
      md << " | | ";
    md << (once ? agreementText((*once)["extra"]["agreement"], false) : "") << " / "
       << (rebuild ? agreementText((*rebuild)["extra"]["agreement"], false) : "") << " |\n";
  }
  md << "\n(trace rate ratio: the toolkit's rays/s over Embree's motion-blur BVH built once; frame total ratio: the "
        "toolkit's update + trace over Embree's per-frame rebuild + trace, below 1 the toolkit is faster; agreement: "
        "the rays whose result equals the toolkit's, the target 99.9%)\n\n";
  return md.str();
}

}  // namespace tsah::bench
