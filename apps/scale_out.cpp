#include "scale_out.hpp"

#include <algorithm>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "cli.hpp"
#if TSAH_HAVE_MPI
#include <mpi.h>
#endif
#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#endif

namespace tsah::cli {

namespace {

int jobRank = 0, jobSize = 1, jobLocalRank = 0;
bool inMpi = false;

#if TSAH_HAVE_MPI
// Started by mpirun (Open MPI) or by srun / another PMI launcher.
bool launchedByMpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

void checkMpi(int code, const char* call) {
  if (code == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  throw Failure(std::string(call) + " failed: " + std::string(text, std::size_t(length)));
}

// Units interleaved over the ranks, each rank's share dealt to its threads, then every unit's
// result gathered on every rank. Static: rank 0 would have to answer requests while it renders to
// deal dynamically, and equal ranks (one GPU or the same cores each) take equal time per unit;
// inside a rank the workers (GPUs of one machine) still take units dynamically.
class MpiDealer final : public WorkDealer {
 public:
  MpiDealer(unsigned workers, std::function<void(unsigned)> start) : local_(workers, std::move(start)) {
    int total = int(workers);
    checkMpi(MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD), "MPI_Allreduce");
    total_ = unsigned(total);
  }
  unsigned localWorkers() const override { return local_.localWorkers(); }
  unsigned totalWorkers() const override { return total_; }

  std::vector<UnitResult> deal(std::span<const uint32_t> units, const UnitWork& work) override {
    std::vector<uint32_t> mine;
    for (std::size_t i = size_t(jobRank); i < units.size(); i += size_t(jobSize)) mine.push_back(units[i]);
    const std::vector<UnitResult> results = local_.deal(mine, work);
    // Mine as one message: each result's size, then the bytes.
    std::vector<uint8_t> packed;
    for (const UnitResult& r : results) {
      const uint64_t n = r.size();
      packed.insert(packed.end(), reinterpret_cast<const uint8_t*>(&n), reinterpret_cast<const uint8_t*>(&n) + 8);
      packed.insert(packed.end(), r.begin(), r.end());
    }
    if (packed.size() > std::size_t(INT_MAX)) throw Failure("MPI: a rank's results exceed 2 GiB");
    const auto ranks = static_cast<std::size_t>(jobSize);
    std::vector<int> sizes(ranks), offsets(ranks);
    const int size = int(packed.size());
    checkMpi(MPI_Allgather(&size, 1, MPI_INT, sizes.data(), 1, MPI_INT, MPI_COMM_WORLD), "MPI_Allgather");
    long long all = 0;
    for (int r = 0; r < jobSize; ++r) {
      offsets[std::size_t(r)] = int(all);
      all += sizes[std::size_t(r)];
    }
    if (all > INT_MAX) throw Failure("MPI: the gathered results exceed 2 GiB");
    std::vector<uint8_t> gathered(std::size_t(all) + 1);
    checkMpi(MPI_Allgatherv(packed.data(), size, MPI_BYTE, gathered.data(), sizes.data(), offsets.data(), MPI_BYTE,
                            MPI_COMM_WORLD),
             "MPI_Allgatherv");
    std::vector<UnitResult> out(units.size());
    for (int r = 0; r < jobSize; ++r) {
      std::size_t at = std::size_t(offsets[std::size_t(r)]);
      for (std::size_t i = std::size_t(r); i < units.size(); i += std::size_t(jobSize)) {
        uint64_t n = 0;
        std::memcpy(&n, gathered.data() + at, 8);
        out[i].assign(gathered.begin() + std::ptrdiff_t(at + 8), gathered.begin() + std::ptrdiff_t(at + 8 + n));
        at += 8 + n;
      }
    }
    return out;
  }

 private:
  ThreadDealer local_;
  unsigned total_ = 1;
};
#endif

int gpuCount() {
#if TSAH_HAVE_CUDA
  return cuda::deviceCount();
#else
  return 0;
#endif
}

}  // namespace

namespace job {

void join(int& argc, char**& argv) {
#if TSAH_HAVE_MPI
  if (!launchedByMpi()) return;
  MPI_Init(&argc, &argv);
  inMpi = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &jobRank);
  MPI_Comm_size(MPI_COMM_WORLD, &jobSize);
  MPI_Comm node;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, jobRank, MPI_INFO_NULL, &node);
  MPI_Comm_rank(node, &jobLocalRank);
  MPI_Comm_free(&node);
#else
  (void)argc;
  (void)argv;
#endif
}

void leave() {
#if TSAH_HAVE_MPI
  if (inMpi) MPI_Finalize();
  inMpi = false;
#endif
}

int rank() { return jobRank; }
int size() { return jobSize; }
int localRank() { return jobLocalRank; }

void fail(const std::string& message, int status) {
  if (jobSize > 1) {
    std::fprintf(stderr, "tsah: rank %d: %s\n", jobRank, message.c_str());
    std::fflush(stderr);
#if TSAH_HAVE_MPI
    MPI_Abort(MPI_COMM_WORLD, status);
#endif
  } else {
    std::fprintf(stderr, "tsah: %s\n", message.c_str());
  }
  leave();
  std::exit(status);
}

}  // namespace job

std::vector<int> parseDevices(const std::string& text) {
  const int count = gpuCount();
  if (count == 0)
    throw UsageError("--devices " + text + ": no CUDA device found (no GPU, no NVIDIA driver, no GPU runtime in this "
                     "build, or CUDA_VISIBLE_DEVICES hides them)");
  std::vector<int> devices;
  if (text == "all") {
    for (int d = 0; d < count; ++d) devices.push_back(d);
    return devices;
  }
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    const bool digits = !item.empty() && item.size() < 4 && item.find_first_not_of("0123456789") == std::string::npos;
    if (!digits) throw UsageError("--devices expects all or GPU indices such as 0,2, got '" + text + "'");
    const int d = std::stoi(item);
    if (d >= count)
      throw UsageError("--devices " + text + ": this machine has " + std::to_string(count) + " GPU(s), 0.." +
                       std::to_string(count - 1));
    if (std::find(devices.begin(), devices.end(), d) != devices.end())
      throw UsageError("--devices " + text + ": GPU " + item + " is given twice");
    devices.push_back(d);
  }
  if (devices.empty()) throw UsageError("--devices expects all or GPU indices such as 0,2, got '" + text + "'");
  return devices;
}

std::pair<uint32_t, uint32_t> parseFrameRange(const std::string& text, uint32_t frames) {
  if (text.empty()) return {0, frames};
  const std::size_t colon = text.find(':');
  auto number = [&](const std::string& part) {
    if (part.empty() || part.size() > 9 || part.find_first_not_of("0123456789") != std::string::npos)
      throw UsageError("--range expects START:END (frame indices, END excluded), got '" + text + "'");
    return uint32_t(std::stoul(part));
  };
  if (colon == std::string::npos) number("");
  const uint32_t start = number(text.substr(0, colon)), end = number(text.substr(colon + 1));
  if (start >= end || end > frames)
    throw UsageError("--range " + text + ": needs 0 <= START < END <= " + std::to_string(frames) +
                     " (the run's frames, END excluded)");
  return {start, end};
}

int rankDevice() {
  const int count = gpuCount();
  return count > 0 ? job::localRank() % count : 0;
}

std::unique_ptr<WorkDealer> makeDealer(unsigned workers, std::function<void(unsigned)> start) {
#if TSAH_HAVE_MPI
  if (job::size() > 1) return std::make_unique<MpiDealer>(workers, std::move(start));
#endif
  return std::make_unique<ThreadDealer>(workers, std::move(start));
}

}  // namespace tsah::cli
