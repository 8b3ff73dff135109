// tsah: one BVH optimized for every frame of an animation (T-SAH), exported and traced.
#include <cstdio>
#include <exception>
#include <new>

#include "cli.hpp"

int main(int argc, char** argv) {
  CLI::App app{"tsah: build one BVH optimized for every frame of an animation (T-SAH), "
               "export it and trace every frame with only a refit."};
  app.set_version_flag("--version", std::string("tsah ") + TSAH_VERSION);
  app.require_subcommand(1);
  tsah::cli::addLoadOptions(app);
  tsah::cli::setupAllCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "tsah: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tsah: %s\n", e.what());
    return 1;
  }
  return 0;
}
