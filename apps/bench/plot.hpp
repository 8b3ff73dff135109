#pragma once
// Line plots through gnuplot for the bench reports: each plot is a PNG with its data file and
// script kept next to it (so a figure can be restyled by hand), the three written as one output set.
#include <filesystem>
#include <string>
#include <vector>

namespace tsah::bench {

struct Series {
  std::string title;
  std::vector<double> x, y;
  bool pointsOnly = false;  // unrelated inputs (real scenes): no line between them
};

class Plotter {
 public:
  Plotter(std::filesystem::path dir, std::string terminal) : dir_(std::move(dir)), terminal_(std::move(terminal)) {}

  // One PNG dir/NAME.png of the series (each its own block in NAME.dat); false with a message in
  // `error` when there is nothing to plot or gnuplot fails.
  bool plot(const std::string& name, const std::string& title, const std::string& xlabel, const std::string& ylabel,
            const std::vector<Series>& series, bool logY, std::string& error, bool logX = false);

 private:
  std::filesystem::path dir_;
  std::string terminal_;
};

// pngcairo draws antialiased lines; the plain png terminal is the fallback.
bool cairoAvailable();
std::string plotTerminal(bool cairo);

}  // namespace tsah::bench
