#pragma once
// Shared pieces of the `tsah` subcommands: self-registration, input loading with progress,
// progress lines on stderr (only on a terminal), and the CLI's error type.
#include <CLI/CLI.hpp>
#include <chrono>
#include <functional>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/load.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/pipeline.hpp"

namespace tsah::cli {

// Exit statuses (README): 0 success, 1 bad input or a failure while working, 2 a usage error (the
// command line itself is wrong: unknown option, value out of range, conflicting choices).
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

// A usage error found by the command line's own option checks (a tsah::ConfigError): main prints
// "tsah: <message>" and exits with kExitUsage. ConfigErrors the library throws exit with
// kExitFailure, as every other error does.
class UsageError : public tsah::ConfigError {
 public:
  using tsah::ConfigError::ConfigError;
};

using CommandSetup = std::function<void(CLI::App& app)>;
// Registers a subcommand; `order` sorts the help listing. Returns true (for static initializers).
bool registerCommand(int order, CommandSetup setup);
// Registers every subcommand, then hardens its numeric options (hardenNumericOptions).
void setupAllCommands(CLI::App& app);
// Every floating-point option of app and its subcommands refuses NaN and infinities, and CLI11's
// PositiveNumber / NonNegativeNumber checks are replaced by ones that refuse NaN and print the value.
void hardenNumericOptions(CLI::App& app);
// A CLI11 message as one line with compact numbers ("0 to 1", not "0.000000 to 1.000000").
std::string compactNumbers(const std::string& text);
// --shutter FRACTION and --shutter-mode centered|open, as trace, export and bench take them.
struct ShutterOptions {
  double fraction = 0.0;          // --shutter
  std::string mode = "centered";  // --shutter-mode
  // Adds both options (--shutter-mode needs --shutter) and returns --shutter.
  CLI::Option* add(CLI::App& sub, const std::string& fractionHelp, const std::string& modeHelp);
  // The shutter; a UsageError "--shutter must be between 0 and 1 (a fraction of FRACTIONOF)" outside [0, 1].
  tsah::Shutter checked(const std::string& fractionOf) const;
};


// An option naming a value of E (tsah/core/kinds.hpp), one of `allowed`: CLI11 refuses any other
// name ("--flag: x not in {a,b}", exit 2) and the value is parsed once, into `target`, by
// tsah::parse. The help shows `target`'s name as the default.
template <typename E>
CLI::Option* addChoice(CLI::App& sub, const std::string& flag, E& target, const std::string& help,
                       std::initializer_list<E> allowed) {
  std::vector<std::string> names;
  for (E value : allowed) names.emplace_back(tsah::name(value));
  return sub
      .add_option_function<std::string>(
          flag, [&target](const std::string& text) { target = tsah::parse<E>(text); }, help)
      ->check(CLI::IsMember(names))
      ->default_str(tsah::name(target));
}

// --layout of trace and bench for --device: auto, or a layout that device traces (cpu: bvh2,
// bvh4, bvh8; cuda: bvh2, cwbvh). Throws UsageError naming the device's layouts otherwise.
void checkLayoutForDevice(Layout layout, Device device);

// True when stderr is a terminal: progress output is shown only then.
bool progressEnabled();

// This process's peak resident memory so far (VmHWM of /proc/self/status), in bytes; 0 when unknown.
// Unlike getrusage's ru_maxrss of a child, it counts this program only: a child started by
// posix_spawn shares its parent's memory until exec, and its ru_maxrss includes the parent's.
double peakResidentBytes();

// Prints a rewriting progress line on stderr ("label: done/total  elapsed"), at most ~10 times/s.
class Progress {
 public:
  explicit Progress(std::string label);
  ~Progress();
  void update(std::size_t done, std::size_t total);
  void message(const std::string& text);  // free-form progress text
  double elapsedSeconds() const;

 private:
  std::string label_;
  std::chrono::steady_clock::time_point start_, last_;
  bool active_ = false;
};

// Import settings given on the command line (--fps, --clip: options of every subcommand that reads
// an animation); loadInput starts from them.
anim::LoadOptions& commandLineLoadOptions();
// Resolves scenes' "data:" paths against the data folder (given, else $TSAH_DATA_DIR, else
// ../shared/data), unpacking archives into `cache` (given, else $TSAH_CACHE_DIR, else
// $XDG_CACHE_HOME/tsah or ~/.cache/tsah). loadInput uses it unless its options have one.
std::function<std::string(const std::string&)> dataPathResolver(const std::string& dataFolder = {},
                                                                const std::string& cache = {});
// Adds --fps and --clip to the top-level app; with fallthrough they may follow any subcommand.
void addLoadOptions(CLI::App& app);

// Loads any input form (see anim::load) with a progress line for long imports.
anim::Animation loadInput(const std::string& input, anim::LoadOptions options = {});

}  // namespace tsah::cli

#define TSAH_CLI_CONCAT_(a, b) a##b
#define TSAH_CLI_CONCAT(a, b) TSAH_CLI_CONCAT_(a, b)
// Use once per cmd_*.cpp: TSAH_REGISTER_COMMAND(order, [](CLI::App& app) { ... });
#define TSAH_REGISTER_COMMAND(order, ...)                                   \
  [[maybe_unused]] static const bool TSAH_CLI_CONCAT(tsahCommand_, __LINE__) = \
      ::tsah::cli::registerCommand(order, __VA_ARGS__)
