// tsah::ThreadDealer (tsah/base/work_dealer.hpp): every unit runs once and comes back in unit order
// whoever ran it, each worker is started once on its own thread, a unit's error is rethrown (the
// lowest unit's), and a worker that cannot start fails the deal.
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>

#include "tsah/base/error.hpp"
#include "tsah/base/work_dealer.hpp"

namespace {

tsah::UnitResult textOf(const std::string& s) { return tsah::UnitResult(s.begin(), s.end()); }

TEST(WorkDealer, EveryUnitOnceInUnitOrder) {
  for (unsigned workers : {1u, 3u, 8u}) {
    std::mutex lock;
    std::set<std::thread::id> starters;
    std::atomic<unsigned> starts{0};
    tsah::ThreadDealer dealer(workers, [&](unsigned) {
      ++starts;
      const std::lock_guard guard(lock);
      starters.insert(std::this_thread::get_id());
    });
    EXPECT_EQ(dealer.localWorkers(), workers);
    const std::vector<uint32_t> units = tsah::unitRange(5, 105);
    std::vector<std::atomic<int>> runs(200);
    const std::vector<tsah::UnitResult> results = dealer.deal(units, [&](uint32_t unit, unsigned worker) {
      EXPECT_LT(worker, workers);
      ++runs[unit];
      return textOf("unit " + std::to_string(unit));
    });
    ASSERT_EQ(results.size(), units.size());
    for (std::size_t i = 0; i < units.size(); ++i) {
      EXPECT_EQ(results[i], textOf("unit " + std::to_string(units[i])));
      EXPECT_EQ(runs[units[i]].load(), 1);
    }
    EXPECT_EQ(starts.load(), workers);  // each worker started once, each on its own thread
    EXPECT_EQ(starters.size(), workers);
  }
  tsah::ThreadDealer empty(4);
  EXPECT_TRUE(empty.deal({}, [](uint32_t, unsigned) { return tsah::UnitResult(); }).empty());
  EXPECT_EQ(tsah::unitRange(3, 3).size(), 0u);
}

TEST(WorkDealer, ErrorsComeBackFromTheLowestFailingUnit) {
  tsah::ThreadDealer dealer(4);
  const std::vector<uint32_t> units = tsah::unitRange(0, 64);
  try {
    dealer.deal(units, [](uint32_t unit, unsigned) -> tsah::UnitResult {
      if (unit == 0) std::this_thread::sleep_for(std::chrono::milliseconds(20));  // fails last
      if (unit % 16 == 0) throw tsah::Failure("unit " + std::to_string(unit) + " failed");
      return {};
    });
    FAIL() << "no error";
  } catch (const tsah::Failure& e) {
    EXPECT_STREQ(e.what(), "unit 0 failed");
  }
  tsah::ThreadDealer refusing(2, [](unsigned worker) {
    if (worker == 1) throw tsah::Failure("GPU 1 refused");
  });
  EXPECT_THROW(refusing.deal(units, [](uint32_t, unsigned) { return tsah::UnitResult(); }), tsah::Failure);
}

}  // namespace
