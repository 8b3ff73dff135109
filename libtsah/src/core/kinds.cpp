#include "tsah/core/kinds.hpp"

#include <span>
#include <type_traits>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

template <typename E>
struct Named {
  E value;
  const char* name;
};

constexpr Named<Layout> kLayouts[] = {
    {Layout::Auto, "auto"}, {Layout::Bvh2, "bvh2"}, {Layout::Bvh4, "bvh4"}, {Layout::Bvh8, "bvh8"}, {Layout::Cwbvh, "cwbvh"}};
constexpr Named<Method> kMethods[] = {
    {Method::Sah0, "sah0"}, {Method::SahStar, "sahstar"}, {Method::SahRebuild, "rebuild"}, {Method::TSah, "tsah"}};
constexpr Named<OptimizerKind> kOptimizers[] = {{OptimizerKind::Sequential, "sequential"},
                                                {OptimizerKind::Parallel, "parallel"}};
constexpr Named<Selection> kSelections[] = {
    {Selection::MetropolisHastings, "mh"}, {Selection::Uniform, "random"}, {Selection::BatchSort, "batch"}};
constexpr Named<Device> kDevices[] = {{Device::Cpu, "cpu"}, {Device::Cuda, "cuda"}};
constexpr Named<SimdIsa> kIsas[] = {{SimdIsa::Sse, "sse"}, {SimdIsa::Avx2, "avx2"}, {SimdIsa::Avx512, "avx512"}};
constexpr Named<TriangleForm> kTriangleForms[] = {{TriangleForm::Woop, "woop"}, {TriangleForm::Vertices, "vertices"}};

// The table of E and the word for E in messages.
template <typename E>
constexpr std::span<const Named<E>> rowsOf() {
  if constexpr (std::is_same_v<E, Layout>) return kLayouts;
  else if constexpr (std::is_same_v<E, Method>) return kMethods;
  else if constexpr (std::is_same_v<E, OptimizerKind>) return kOptimizers;
  else if constexpr (std::is_same_v<E, Selection>) return kSelections;
  else if constexpr (std::is_same_v<E, Device>) return kDevices;
  else if constexpr (std::is_same_v<E, SimdIsa>) return kIsas;
  else return kTriangleForms;
}

template <typename E>
constexpr const char* kindOf() {
  if constexpr (std::is_same_v<E, Layout>) return "layout";
  else if constexpr (std::is_same_v<E, Method>) return "method";
  else if constexpr (std::is_same_v<E, OptimizerKind>) return "optimizer";
  else if constexpr (std::is_same_v<E, Selection>) return "node selection";
  else if constexpr (std::is_same_v<E, Device>) return "device";
  else if constexpr (std::is_same_v<E, SimdIsa>) return "instruction set";
  else return "triangle form";
}

template <typename E>
const char* nameOf(E value) {
  for (const auto& row : rowsOf<E>())
    if (row.value == value) return row.name;
  return "?";
}

}  // namespace

const char* name(Layout value) { return nameOf(value); }
const char* name(Method value) { return nameOf(value); }
const char* name(OptimizerKind value) { return nameOf(value); }
const char* name(Selection value) { return nameOf(value); }
const char* name(Device value) { return nameOf(value); }
const char* name(SimdIsa value) { return nameOf(value); }
const char* name(TriangleForm value) { return nameOf(value); }

template <typename E>
std::string choices() {
  std::string out;
  const auto rows = rowsOf<E>();
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (i) out += i + 1 == rows.size() ? " or " : ", ";
    out += rows[i].name;
  }
  return out;
}

template <typename E>
E parse(std::string_view text) {
  for (const auto& row : rowsOf<E>())
    if (text == row.name) return row.value;
  throw ConfigError("unknown " + std::string(kindOf<E>()) + " '" + std::string(text) + "' (expected " + choices<E>() +
                    ")");
}

template Layout parse<Layout>(std::string_view);
template Method parse<Method>(std::string_view);
template OptimizerKind parse<OptimizerKind>(std::string_view);
template Selection parse<Selection>(std::string_view);
template Device parse<Device>(std::string_view);
template SimdIsa parse<SimdIsa>(std::string_view);
template TriangleForm parse<TriangleForm>(std::string_view);
template std::string choices<Layout>();
template std::string choices<Method>();
template std::string choices<OptimizerKind>();
template std::string choices<Selection>();
template std::string choices<Device>();
template std::string choices<SimdIsa>();
template std::string choices<TriangleForm>();

}  // namespace tsah
