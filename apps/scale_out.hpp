#pragma once
// Scale-out of the tsah program (docs/scale-out.md): the MPI job this process belongs to, the GPUs
// of --devices, and the one WorkDealer (tsah/base/work_dealer.hpp) that trace and
// optimize --segments deal their units with: units interleaved over the job's ranks (rank r takes
// units r, r + R, ...), inside a rank taken one after the other by its workers (one per GPU, or
// one CPU runtime), the results gathered on every rank.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "tsah/base/work_dealer.hpp"

namespace tsah::cli {

// The job: a process alone (a build without MPI, or one not started by mpirun / srun), or one rank
// of an MPI job.
namespace job {
// Joins the MPI job when started by mpirun or srun (before any thread exists); leave() at exit.
void join(int& argc, char**& argv);
void leave();
int rank();
int size();
// This rank's index among the ranks of its machine (its GPU), 0 alone.
int localRank();
inline bool leader() { return rank() == 0; }
// Prints "tsah: MESSAGE" on stderr, naming the rank when the job has several ("tsah: rank R:
// MESSAGE"), and ends the whole job with `status` (MPI_Abort: no rank waits on a failed one).
[[noreturn]] void fail(const std::string& message, int status);
}  // namespace job

// --devices all|I,J,...: the GPU indices, in the order given. Throws UsageError without a GPU (or
// without the GPU runtime), for an index the machine lacks, a repeated index or bad text.
std::vector<int> parseDevices(const std::string& text);
// The GPU of this process for --device cuda without --devices: its local rank's, modulo the GPUs
// of the machine (0 alone).
int rankDevice();

// --range START:END of a run of `frames` frames: the half-open range [START, END) of frame indices;
// empty text: every frame. Throws UsageError for bad text or bounds outside 0 <= START < END <= frames.
std::pair<uint32_t, uint32_t> parseFrameRange(const std::string& text, uint32_t frames);

// The dealer of this process: `workers` local workers (each after start(worker) on its thread),
// and the job's ranks.
std::unique_ptr<WorkDealer> makeDealer(unsigned workers, std::function<void(unsigned worker)> start = {});

}  // namespace tsah::cli
