#pragma once
// Running the external programs the bench needs (tar and xz to unpack data, gnuplot for plots)
// without a shell: arguments are passed as they are, so no path is ever interpreted.
#include <string>
#include <vector>

namespace tsah::bench {

struct ProcessResult {
  bool started = false;  // false: the program could not be run at all (not installed)
  int status = -1;       // exit status (128 + signal when killed by a signal)
  std::string output;    // what it wrote on stderr (and stdout unless redirected), at most 64 KiB
  long maxRssKb = 0;     // its peak resident memory (getrusage ru_maxrss of the child, KiB)
  double cpuSeconds = 0; // its user + system CPU time
  bool ok() const { return started && status == 0; }
};

// Runs argv[0] (searched in PATH) with the remaining arguments and waits for it. stdoutPath: a file
// that receives its standard output (created or truncated); empty: stdout is captured with stderr.
ProcessResult runProcess(const std::vector<std::string>& argv, const std::string& stdoutPath = {});

// True when `name` is an executable file in PATH.
bool programInPath(const std::string& name);

}  // namespace tsah::bench
