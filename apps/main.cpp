// tsah: one BVH optimized for every frame of an animation (T-SAH), exported and traced.
#include <cstdio>
#include <exception>
#include <new>
#include <string>

#include "tsah/base/files.hpp"
#include "cli.hpp"
#include "scale_out.hpp"

namespace {

// An error of the command: one line and its exit status; in an MPI job one line naming the rank,
// and the whole job ends (no rank left waiting on this one).
int failWith(const std::string& raw, int status) {
  const std::string message = tsah::printable(raw);
  if (tsah::cli::job::size() > 1) tsah::cli::job::fail(message, status);
  std::fprintf(stderr, "tsah: %s\n", message.c_str());
  return status;
}

int run(int argc, char** argv);

}  // namespace

// Every message is printed through tsah::printable: a control character in a name (a line break in
// a file name) is written as \xHH, so the message stays one line.
int main(int argc, char** argv) {
  tsah::cli::job::join(argc, argv);  // before any thread exists
  const int status = run(argc, argv);
  tsah::cli::job::leave();
  return status;
}

namespace {

int run(int argc, char** argv) {
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
    return tsah::cli::job::leader() ? app.exit(e) : 0;
  } catch (const CLI::RuntimeError& e) {  // a command's own exit status
    return e.get_exit_code();
  } catch (const CLI::ParseError& e) {  // the same on every rank: said once
    if (tsah::cli::job::leader())
      std::fprintf(stderr, "tsah: %s (tsah --help lists the options)\n",
                   tsah::printable(tsah::cli::compactNumbers(e.what())).c_str());
    return tsah::cli::kExitUsage;
  } catch (const tsah::cli::UsageError& e) {
    return failWith(e.what(), tsah::cli::kExitUsage);
  } catch (const std::bad_alloc&) {
    return failWith("out of memory", tsah::cli::kExitFailure);
  } catch (const std::exception& e) {
    return failWith(e.what(), tsah::cli::kExitFailure);
  }
  return 0;
}

}  // namespace
