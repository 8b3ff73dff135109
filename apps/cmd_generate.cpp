// tsah generate KIND -o OUT: procedural sample animations.
#include <cstdio>

#include "anim/generators.hpp"
#include "anim/obj_writer.hpp"
#include "anim/tanim.hpp"
#include "cli.hpp"

TSAH_REGISTER_COMMAND(20, [](CLI::App& app) {
  auto* sub = app.add_subcommand("generate", "Generate a sample animation (deterministic for a seed)");
  struct Options {
    std::string kind, output;
    uint32_t triangles = 4000, frames = 30;
    uint64_t seed = 1;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("KIND", opt->kind, "explode (fragments fly apart), wave (cloth-like sheet), "
                                     "swap (two groups pass through each other)")
      ->required()
      ->check(CLI::IsMember({"explode", "wave", "swap"}));
  sub->add_option("-o,--output", opt->output,
                  "Output: a .tanim file, or an OBJ sequence pattern such as frames/f_%04d.obj")
      ->required();
  sub->add_option("--triangles", opt->triangles, "Approximate triangle count")->capture_default_str();
  sub->add_option("--frames", opt->frames, "Keyframes")->capture_default_str();
  sub->add_option("--seed", opt->seed, "Random seed")->capture_default_str();
  sub->callback([opt] {
    anim::GeneratorOptions g;
    g.triangles = opt->triangles;
    g.frames = opt->frames;
    g.seed = opt->seed;
    const anim::Animation a = anim::generate(anim::parseGeneratorKind(opt->kind), g);
    if (opt->output.find('%') != std::string::npos)
      anim::saveObjSequence(a, opt->output);
    else
      anim::saveTanim(a, opt->output);
    std::printf("%s: %s, %u triangles, %u vertices, %u keyframes\n", opt->output.c_str(), opt->kind.c_str(),
                a.triangleCount(), a.vertexCount(), a.keyframeCount());
  });
});
