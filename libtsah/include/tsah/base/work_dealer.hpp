#pragma once
// Independent units of work (the frames of `tsah trace`, the candidate trees of a tree-set search)
// dealt to workers: the threads of this process (each may own a GPU) and, through a subclass the
// tsah program provides, the ranks of an MPI job. Each unit runs exactly once and turns into bytes;
// every process gets every unit's bytes back in unit order, so what follows does not depend on who
// ran what (every split gives the same output).
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace tsah {

using UnitResult = std::vector<uint8_t>;
// work(unit, worker): the unit's result; `worker` (0 .. localWorkers() - 1) names the thread of
// this process that runs it, so that it can use what that worker owns (its GPU runtime).
using UnitWork = std::function<UnitResult(uint32_t unit, unsigned worker)>;

class WorkDealer {
 public:
  virtual ~WorkDealer() = default;
  // Workers of this process, and of all processes together (what a search may speculate on).
  virtual unsigned localWorkers() const = 0;
  virtual unsigned totalWorkers() const { return localWorkers(); }
  // Runs work for every unit in `units` and returns their results in the order of `units`. An error
  // of a unit is rethrown here after the other workers stopped taking units (the lowest such unit's
  // error, so that the message does not depend on timing); so is the error of a worker that could
  // not start.
  virtual std::vector<UnitResult> deal(std::span<const uint32_t> units, const UnitWork& work) = 0;
};

// The threads of this process: worker 0 is the calling thread, the others are started per deal
// (each after start(worker), e.g. choosing its GPU). Units are taken in order from a shared
// counter, so a faster worker takes more.
class ThreadDealer final : public WorkDealer {
 public:
  explicit ThreadDealer(unsigned workers, std::function<void(unsigned worker)> start = {});
  unsigned localWorkers() const override { return workers_; }
  std::vector<UnitResult> deal(std::span<const uint32_t> units, const UnitWork& work) override;

 private:
  unsigned workers_;
  std::function<void(unsigned)> start_;
};

// The units [begin, end).
std::vector<uint32_t> unitRange(uint32_t begin, uint32_t end);

}  // namespace tsah
