// tsah: one BVH optimized for every frame of an animation (T-SAH), exported and traced.
#include <cstdio>
#include <exception>
#include <new>

#include "tsah/base/files.hpp"
#include "cli.hpp"

// Every message is printed through tsah::printable: a control character in a name (a line break in
// a file name) is written as \xHH, so the message stays one line.
int main(int argc, char** argv) {
  // Before any thread exists: SIGINT/SIGTERM remove the temporaries in flight (no partial files).
  tsah::installInterruptCleanup();
  tsah::protectInputs(true);  // an output may never replace one of the command's inputs
  CLI::App app{"tsah: build one BVH optimized for every frame of an animation (T-SAH), "
               "export it and trace every frame with only a refit."};
  app.set_version_flag("--version", std::string("tsah ") + TSAH_VERSION);
  app.require_subcommand(1);
  tsah::cli::addLoadOptions(app);
  tsah::cli::setupAllCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::RuntimeError& e) {  // a command's own exit status
    return e.get_exit_code();
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "tsah: %s (tsah --help lists the options)\n", tsah::printable(tsah::cli::compactNumbers(e.what())).c_str());
    return tsah::cli::kExitUsage;
  } catch (const tsah::cli::UsageError& e) {
    std::fprintf(stderr, "tsah: %s\n", tsah::printable(e.what()).c_str());
    return tsah::cli::kExitUsage;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "tsah: out of memory\n");
    return tsah::cli::kExitFailure;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tsah: %s\n", tsah::printable(e.what()).c_str());
    return tsah::cli::kExitFailure;
  }
  return 0;
}
