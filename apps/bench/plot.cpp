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
  const fs::path dat = dir_ / (name + ".dat"), gp = dir_ / (name + ".gp"), png = dir_ / (name + ".png");
  const fs::path tmp = dir_ / (name + ".png.tmp");
  std::ostringstream script;
  script << "set terminal " << terminal_ << "\nset output " << quoted(tmp.string()) << "\nset title "
         << quoted(title) << "\nset xlabel " << quoted(xlabel) << "\nset ylabel " << quoted(ylabel)
         << "\nset grid\nset key outside right top\n"
         << (logY ? "set logscale y\n" : "") << (logX ? "set logscale x\n" : "") << "plot ";
  bool first = true;
  for (std::size_t s = 0; s < series.size(); ++s) {
    if (series[s].x.empty()) continue;
    script << (first ? "" : ", \\\n     ") << quoted(dat.string()) << " index " << s
           << " using 1:2 with " << (series[s].pointsOnly ? "points pt 7 ps 1.2" : "linespoints pt 7 ps 0.5 lw 2")
           << " title " << quoted(series[s].title);
    first = false;
  }
  script << "\nunset output\n";
  if (first) {
    error = name + ": nothing to plot";
    return false;
  }
  const std::string d = data.str(), g = script.str();
  tsah::writeFileAtomically(dat.string(), std::span(reinterpret_cast<const uint8_t*>(d.data()), d.size()));
  tsah::writeFileAtomically(gp.string(), std::span(reinterpret_cast<const uint8_t*>(g.data()), g.size()));
  const ProcessResult r = runProcess({"gnuplot", gp.string()});
  std::error_code ec;
  if (!r.ok() || !fs::exists(tmp, ec)) {
    fs::remove(tmp, ec);
    error = name + ": gnuplot failed" + (r.output.empty() ? "" : ": " + r.output.substr(0, r.output.find('\n')));
    return false;
  }
  fs::rename(tmp, png, ec);
  if (ec) {
    error = png.string() + ": " + ec.message();
    return false;
  }
  return true;
}

bool cairoAvailable() { return runProcess({"gnuplot", "-e", "set terminal pngcairo"}).ok(); }

std::string plotTerminal(bool cairo) {
  return cairo ? "pngcairo size 960,540 noenhanced font ',10'" : "png size 960,540 noenhanced";
}

}  // namespace tsah::bench
