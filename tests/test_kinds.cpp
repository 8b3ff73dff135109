// The named choices of the library boundary (tsah/core/kinds.hpp): every name parses back to its
// value, anything else is refused with one ConfigError that lists the choices.
#include <gtest/gtest.h>

#include <string>

#include "tsah/base/error.hpp"
#include "tsah/core/kinds.hpp"

namespace {

template <typename E>
void expectRoundTrip(std::initializer_list<E> values, const std::string& expectedChoices) {
  for (E value : values) EXPECT_EQ(tsah::parse<E>(tsah::name(value)), value) << tsah::name(value);
  EXPECT_EQ(tsah::choices<E>(), expectedChoices);
  try {
    tsah::parse<E>("Bogus");
    ADD_FAILURE() << "an unknown name was accepted";
  } catch (const tsah::ConfigError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'Bogus' (expected " + expectedChoices + ")"), std::string::npos) << what;
  }
}

TEST(Kinds, EveryNameRoundTripsAndUnknownNamesAreRefused) {
  using namespace tsah;
  expectRoundTrip({Layout::Auto, Layout::Bvh2, Layout::Bvh4, Layout::Bvh8, Layout::Cwbvh},
                  "auto, bvh2, bvh4, bvh8 or cwbvh");
  expectRoundTrip({Method::Sah0, Method::SahStar, Method::SahRebuild, Method::TSah}, "sah0, sahstar, rebuild or tsah");
  expectRoundTrip({OptimizerKind::Sequential, OptimizerKind::Parallel}, "sequential or parallel");
  expectRoundTrip({Selection::MetropolisHastings, Selection::Uniform, Selection::BatchSort}, "mh, random or batch");
  expectRoundTrip({Device::Cpu, Device::Cuda}, "cpu or cuda");
  expectRoundTrip({SimdIsa::Sse, SimdIsa::Avx2, SimdIsa::Avx512}, "sse, avx2 or avx512");
}

TEST(Kinds, NamesAreCaseSensitiveAndWhole) {
  EXPECT_THROW(tsah::parse<tsah::Layout>("BVH8"), tsah::ConfigError);
  EXPECT_THROW(tsah::parse<tsah::Layout>("bvh8 "), tsah::ConfigError);
  EXPECT_THROW(tsah::parse<tsah::Device>(""), tsah::ConfigError);
}

TEST(Kinds, CpuLayoutWidths) {
  EXPECT_EQ(tsah::layoutWidth(tsah::Layout::Bvh2), 2u);
  EXPECT_EQ(tsah::layoutWidth(tsah::Layout::Bvh4), 4u);
  EXPECT_EQ(tsah::layoutWidth(tsah::Layout::Bvh8), 8u);
  EXPECT_EQ(tsah::layoutWidth(tsah::Layout::Cwbvh), 0u);
  EXPECT_EQ(tsah::layoutWidth(tsah::Layout::Auto), 0u);
}

}  // namespace
