#include "tsah/base/work_dealer.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <numeric>
#include <thread>

namespace tsah {

ThreadDealer::ThreadDealer(unsigned workers, std::function<void(unsigned)> start)
    : workers_(std::max(1u, workers)), start_(std::move(start)) {}

std::vector<UnitResult> ThreadDealer::deal(std::span<const uint32_t> units, const UnitWork& work) {
  std::vector<UnitResult> results(units.size());
  std::vector<std::exception_ptr> errors(units.size());
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::vector<std::exception_ptr> startErrors(workers_);
  auto run = [&](unsigned worker) {
    try {
      if (start_) start_(worker);
    } catch (...) {  // a worker that cannot start (its GPU refused) fails the deal
      startErrors[worker] = std::current_exception();
      failed = true;
      return;
    }
    for (std::size_t i; !failed && (i = next.fetch_add(1)) < units.size();) {
      try {
        results[i] = work(units[i], worker);
      } catch (...) {
        errors[i] = std::current_exception();
        failed = true;
      }
    }
  };
  const unsigned helpers = unsigned(std::min<std::size_t>(workers_, units.size())) - (units.empty() ? 0 : 1);
  std::vector<std::thread> pool;
  for (unsigned w = 1; w <= helpers; ++w) pool.emplace_back(run, w);
  if (!units.empty()) run(0);
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
  for (const std::exception_ptr& e : startErrors)
    if (e) std::rethrow_exception(e);
  return results;
}

std::vector<uint32_t> unitRange(uint32_t begin, uint32_t end) {
  std::vector<uint32_t> units(end > begin ? end - begin : 0);
  std::iota(units.begin(), units.end(), begin);
  return units;
}

}  // namespace tsah
