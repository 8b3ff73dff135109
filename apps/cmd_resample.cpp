// tsah resample INPUT -o OUT.tanim [--frames N]
#include <cstdio>

#include "anim/tanim.hpp"
#include "cli.hpp"

TSAH_REGISTER_COMMAND(30, [](CLI::App& app) {
  auto* sub = app.add_subcommand("resample", "Resample an animation into N uniformly spaced frames (.tanim)");
  struct Options {
    std::string input, output;
    uint32_t frames = 0;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("INPUT", opt->input, "Any animation input")->required();
  sub->add_option("-o,--output", opt->output, "Output .tanim file")->required();
  sub->add_option("--frames", opt->frames, "Uniformly spaced frames over the time range (default: keep every keyframe)")
      ->check(CLI::Range(1u, 1000000u));
  sub->callback([opt] {
    const anim::Animation input = tsah::cli::loadInput(opt->input);
    const anim::Animation out = opt->frames ? input.resample(opt->frames) : input;
    anim::saveTanim(out, opt->output);
    std::printf("%s: %u keyframes (from %u), %u triangles, time %g .. %g\n", opt->output.c_str(),
                out.keyframeCount(), input.keyframeCount(), out.triangleCount(), out.startTime(), out.endTime());
  });
});
