// tsah report STATS.json... [--json]: the statistics of a run's chunks (`tsah trace --range ...
// --stats FILE`) merged into the summary the whole run prints.
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli.hpp"
#include "trace_report.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"

TSAH_REGISTER_COMMAND(75, [](CLI::App& app) {
  auto* sub = app.add_subcommand(
      "report", "Merge the statistics of a run's chunks (tsah trace --range --stats) into the whole run's summary");
  struct Options {
    std::vector<std::string> files;
    bool json = false;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("STATS", opt->files, "The chunks' --stats files, in any order")->required();
  sub->add_flag("--json", opt->json, "Print the whole run's JSON object (as tsah trace --json prints it)");
  sub->callback([opt] {
    std::vector<std::pair<std::string, nlohmann::json>> chunks;
    for (const std::string& file : opt->files) {
      const std::vector<uint8_t> bytes = tsah::readFile(file, std::size_t(1) << 30);
      nlohmann::json run = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
      if (run.is_discarded()) throw tsah::FileError(file, "not JSON");
      chunks.emplace_back(file, std::move(run));
    }
    const nlohmann::json run = tsah::cli::mergeChunks(chunks);
    if (opt->json)
      std::printf("%s\n", run.dump().c_str());
    else
      tsah::cli::printTraceSummary(run);
  });
});
