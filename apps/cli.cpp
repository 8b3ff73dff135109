#include "cli.hpp"

#include "bench/data_scan.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <cstdio>
#include <unistd.h>
#include <utility>
#include <vector>

namespace tsah::cli {

namespace {
std::vector<std::pair<int, CommandSetup>>& registry() {
  static std::vector<std::pair<int, CommandSetup>> commands;
  return commands;
}
}  // namespace

bool registerCommand(int order, CommandSetup setup) {
  registry().emplace_back(order, std::move(setup));
  return true;
}

namespace {

// Parses a whole option value as a double (what CLI11 stores in a floating-point option).
bool parseDouble(const std::string& text, double& value) {
  char* end = nullptr;
  errno = 0;
  value = std::strtod(text.c_str(), &end);
  return !text.empty() && end == text.c_str() + text.size();
}

// The checks every numeric option gets: CLI11's PositiveNumber and NonNegativeNumber let NaN through
// (every comparison with NaN is false) and print DBL_MAX with 309 digits.
std::string finiteCheck(std::string& text) {
  double v = 0;
  if (parseDouble(text, v) && !std::isfinite(v)) return "must be a finite number, got " + text;
  return {};
}
std::function<std::string(std::string&)> lowerBound(bool strict) {
  return [strict](std::string& text) -> std::string {
    double v = 0;
    const char* what = strict ? "must be a positive finite number, got " : "must be a non-negative finite number, got ";
    if (!parseDouble(text, v) || !std::isfinite(v) || (strict ? !(v > 0) : !(v >= 0))) return what + text;
    return {};
  };
}

}  // namespace

void hardenNumericOptions(CLI::App& app) {
  for (CLI::Option* option : app.get_options()) {
    // CLI11 2.1 keeps "POSITIVE"/"NONNEGATIVE" as the validators' descriptions, not their names.
    for (int i = 0;; ++i) {
      CLI::Validator* v = nullptr;
      try {
        v = option->get_validator(i);
      } catch (const CLI::OptionNotFound&) {
        break;
      }
      const std::string kind = v->get_description();
      if (kind == "POSITIVE" || kind == "NONNEGATIVE") v->operation(lowerBound(kind == "POSITIVE"));
    }
    if (option->get_type_name().rfind("FLOAT", 0) == 0) option->check(CLI::Validator(finiteCheck, "", "FINITE"));
  }
  for (CLI::App* sub : app.get_subcommands({})) hardenNumericOptions(*sub);
}

std::string compactNumbers(const std::string& text) {
  // CLI11 prints range limits with std::to_string ("0.000000", or DBL_MAX as 309 digits).
  static const std::regex fixed("-?[0-9]+\\.[0-9]{6}");
  std::string out;
  auto begin = std::sregex_iterator(text.begin(), text.end(), fixed);
  std::size_t last = 0;
  for (auto it = begin; it != std::sregex_iterator(); ++it) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", std::strtod(it->str().c_str(), nullptr));
    out.append(text, last, std::size_t(it->position()) - last).append(buf);
    last = std::size_t(it->position() + it->length());
  }
  out.append(text, last);
  std::replace(out.begin(), out.end(), '\n', ' ');
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

void setupAllCommands(CLI::App& app) {
  auto& commands = registry();
  std::stable_sort(commands.begin(), commands.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (auto& [order, setup] : commands) setup(app);
  hardenNumericOptions(app);
}

void checkLayoutForDevice(Layout layout, Device device) {
  const bool gpu = device == Device::Cuda;
  const bool ok = layout == Layout::Auto || layout == Layout::Bvh2 ||
                  (gpu ? layout == Layout::Cwbvh : layout == Layout::Bvh4 || layout == Layout::Bvh8);
  if (!ok)
    throw UsageError(std::string("--layout ") + name(layout) + " is not a layout of --device " + name(device) + " (" +
                     (gpu ? "auto, bvh2 or cwbvh" : "auto, bvh2, bvh4 or bvh8") + ")");
}

bool progressEnabled() {
  static const bool enabled = ::isatty(STDERR_FILENO) == 1;
  return enabled;
}

double peakResidentBytes() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0.0;
  char line[256];
  double kib = 0.0;
  while (std::fgets(line, sizeof line, f))
    if (std::sscanf(line, "VmHWM: %lf kB", &kib) == 1) break;
  std::fclose(f);
  return kib * 1024.0;
}

Progress::Progress(std::string label)
    : label_(std::move(label)), start_(std::chrono::steady_clock::now()), last_(start_) {}

Progress::~Progress() {
  if (active_) std::fputs("\r\033[K", stderr);
}

double Progress::elapsedSeconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::update(std::size_t done, std::size_t total) {
  message(std::to_string(done) + "/" + std::to_string(total));
}

void Progress::message(const std::string& text) {
  if (!progressEnabled()) return;
  const auto now = std::chrono::steady_clock::now();
  if (active_ && now - last_ < std::chrono::milliseconds(100)) return;
  last_ = now;
  active_ = true;
  std::fprintf(stderr, "\r\033[K%s: %s  %.1fs", label_.c_str(), text.c_str(), elapsedSeconds());
  std::fflush(stderr);
}

std::function<std::string(const std::string&)> dataPathResolver(const std::string& dataFolder,
                                                                const std::string& cache) {
  return tsah::bench::dataPathResolver(dataFolder, cache, TSAH_SOURCE_DIR);
}

anim::LoadOptions& commandLineLoadOptions() {
  static anim::LoadOptions options;
  return options;
}

void addLoadOptions(CLI::App& app) {
  app.fallthrough();
  app.add_option("--fps", commandLineLoadOptions().fps,
                 "Sampling rate for BART scenes and animated models (default: the file's own frames)")
      ->check(CLI::Range(0.0, anim::LoadOptions::kMaxFps));
  app.add_option("--clip", commandLineLoadOptions().clip,
                 "Animation clip to bake when a model holds several (name or index)");
}

CLI::Option* ShutterOptions::add(CLI::App& sub, const std::string& fractionHelp, const std::string& modeHelp) {
  CLI::Option* shutter = sub.add_option("--shutter", fraction, fractionHelp);
  sub.add_option("--shutter-mode", mode, modeHelp)->check(CLI::IsMember({"centered", "open"}))->needs(shutter);
  return shutter;
}

tsah::Shutter ShutterOptions::checked(const std::string& fractionOf) const {
  if (!(fraction >= 0.0 && fraction <= 1.0))
    throw UsageError("--shutter must be between 0 and 1 (a fraction of " + fractionOf + ")");
  tsah::Shutter shutter;
  shutter.fraction = fraction;
  shutter.mode = mode == "open" ? tsah::Shutter::Mode::Open : tsah::Shutter::Mode::Centered;
  return shutter;
}

anim::Animation loadInput(const std::string& input, anim::LoadOptions options) {
  if (options.fps == 0.0) options.fps = commandLineLoadOptions().fps;
  if (options.clip.empty()) options.clip = commandLineLoadOptions().clip;
  Progress progress("loading " + input);
  if (!options.progress)
    options.progress = [&](std::size_t done, std::size_t total) { progress.update(done, total); };
  // Importer warnings (skipped materials, transforms without keys, ...) go to stderr, one line each,
  // so stdout stays a clean result (--json).
  if (!options.warning)
    options.warning = [](const std::string& text) { std::fprintf(stderr, "tsah: warning: %s\n", text.c_str()); };
  if (!options.resolveDataPath) options.resolveDataPath = dataPathResolver();
  return anim::load(input, options);
}

}  // namespace tsah::cli
