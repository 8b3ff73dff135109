#include "bench/plot.hpp"

#include <sstream>
#include <span>

#include "tsah/base/files.hpp"
#include "bench/process.hpp"

namespace tsah::bench {

namespace fs = std::filesystem;

namespace {

// A gnuplot single-quoted string: a quote inside is written twice.
std::string quoted(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

}  // namespace

bool Plotter::plot(const std::string& name, const std::string& title, const std::string& xlabel,
                   const std::string& ylabel, const std::vector<Series>& series, bool logY, std::string& error,
                   bool logX) {
  std::ostringstream data;
  for (std::size_t s = 0; s < series.size(); ++s) {
    data << "# " << series[s].title << "\n";
    for (std::size_t i = 0; i < series[s].x.size() && i < series[s].y.size(); ++i)
      data << series[s].x[i] << " " << series[s].y[i] << "\n";
    data << "\n\n";
  }
  // The PNG, its data and its script are one output set: all three appear or none. The script
  // names its files relative to its own folder, so it can be rerun there by hand to restyle a figure.
  const std::string dat = name + ".dat", gp = name + ".gp", png = name + ".png";
  std::ostringstream script;
  script << "set terminal " << terminal_ << "\nset output " << quoted(png) << "\nset title " << quoted(title)
         << "\nset xlabel " << quoted(xlabel) << "\nset ylabel " << quoted(ylabel)
         << "\nset grid\nset key outside right top\n"
         << (logY ? "set logscale y\n" : "") << (logX ? "set logscale x\n" : "") << "plot ";
  bool first = true;
  for (std::size_t s = 0; s < series.size(); ++s) {
    if (series[s].x.empty()) continue;
    script << (first ? "" : ", \\\n     ") << quoted(dat) << " index " << s << " using 1:2 with "
           << (series[s].pointsOnly ? "points pt 7 ps 1.2" : "linespoints pt 7 ps 0.5 lw 2") << " title "
           << quoted(series[s].title);
    first = false;
  }
  script << "\nunset output\n";
  if (first) {
    error = name + ": nothing to plot";
    return false;
  }
  tsah::AtomicFileSet files;
  files.write((dir_ / dat).string(), data.str());
  files.write((dir_ / gp).string(), script.str());
  const fs::path stagedPng = files.stage((dir_ / png).string());
  // gnuplot runs in the staging folder, where the script finds its data and writes the PNG.
  const ProcessResult r = runProcess({"gnuplot", "-e", "cd " + quoted(stagedPng.parent_path().string()), gp});
  std::error_code ec;
  if (!r.ok() || !fs::exists(stagedPng, ec)) {
    error = name + ": gnuplot failed" + (r.output.empty() ? "" : ": " + r.output.substr(0, r.output.find('\n')));
    return false;
  }
  files.commit();
  return true;
}

bool cairoAvailable() { return runProcess({"gnuplot", "-e", "set terminal pngcairo"}).ok(); }

std::string plotTerminal(bool cairo) {
  return cairo ? "pngcairo size 960,540 noenhanced font ',10'" : "png size 960,540 noenhanced";
}

}  // namespace tsah::bench
