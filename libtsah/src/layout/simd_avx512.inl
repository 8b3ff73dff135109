// V4 and V8 with AVX-512VL: the same lanes as the SSE / AVX types, but comparisons produce mask
// registers (__mmask8), combined with k-register logic and read without a movemask. Included
// inside the instruction-set namespace of wide_kernels_avx512.cpp; no includes here.
struct Mask8 {
  __mmask8 m;
  friend Mask8 operator&(Mask8 a, Mask8 b) { return {_kand_mask8(a.m, b.m)}; }
  friend Mask8 operator|(Mask8 a, Mask8 b) { return {_kor_mask8(a.m, b.m)}; }
};

struct V4 {
  static constexpr uint32_t N = 4;
  using Mask = Mask8;
  __m128 v;
  static V4 set1(float x) { return {_mm_set1_ps(x)}; }
  static V4 load(const float* p) { return {_mm_load_ps(p)}; }
  static void store(float* p, V4 a) { _mm_store_ps(p, a.v); }
  friend V4 operator+(V4 a, V4 b) { return {_mm_add_ps(a.v, b.v)}; }
  friend V4 operator-(V4 a, V4 b) { return {_mm_sub_ps(a.v, b.v)}; }
  friend V4 operator*(V4 a, V4 b) { return {_mm_mul_ps(a.v, b.v)}; }
  friend V4 operator/(V4 a, V4 b) { return {_mm_div_ps(a.v, b.v)}; }
  static V4 min(V4 a, V4 b) { return {_mm_min_ps(a.v, b.v)}; }
  static V4 max(V4 a, V4 b) { return {_mm_max_ps(a.v, b.v)}; }
  static V4 abs(V4 a) { return {_mm_andnot_ps(_mm_set1_ps(-0.0f), a.v)}; }
  static Mask lt(V4 a, V4 b) { return {_mm_cmp_ps_mask(a.v, b.v, _CMP_LT_OQ)}; }
  static Mask le(V4 a, V4 b) { return {_mm_cmp_ps_mask(a.v, b.v, _CMP_LE_OQ)}; }
  static Mask gt(V4 a, V4 b) { return {_mm_cmp_ps_mask(a.v, b.v, _CMP_GT_OQ)}; }
  static Mask andNot(Mask a, Mask b) { return {_kandn_mask8(a.m, b.m)}; }  // ~a & b
  static uint32_t bits(Mask a) { return uint32_t(a.m) & 0xfu; }
};

struct V8 {
  static constexpr uint32_t N = 8;
  using Mask = Mask8;
  __m256 v;
  static V8 set1(float x) { return {_mm256_set1_ps(x)}; }
  static V8 load(const float* p) { return {_mm256_load_ps(p)}; }
  static void store(float* p, V8 a) { _mm256_store_ps(p, a.v); }
  friend V8 operator+(V8 a, V8 b) { return {_mm256_add_ps(a.v, b.v)}; }
  friend V8 operator-(V8 a, V8 b) { return {_mm256_sub_ps(a.v, b.v)}; }
  friend V8 operator*(V8 a, V8 b) { return {_mm256_mul_ps(a.v, b.v)}; }
  friend V8 operator/(V8 a, V8 b) { return {_mm256_div_ps(a.v, b.v)}; }
  static V8 min(V8 a, V8 b) { return {_mm256_min_ps(a.v, b.v)}; }
  static V8 max(V8 a, V8 b) { return {_mm256_max_ps(a.v, b.v)}; }
  static V8 abs(V8 a) { return {_mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v)}; }
  static Mask lt(V8 a, V8 b) { return {_mm256_cmp_ps_mask(a.v, b.v, _CMP_LT_OQ)}; }
  static Mask le(V8 a, V8 b) { return {_mm256_cmp_ps_mask(a.v, b.v, _CMP_LE_OQ)}; }
  static Mask gt(V8 a, V8 b) { return {_mm256_cmp_ps_mask(a.v, b.v, _CMP_GT_OQ)}; }
  static Mask andNot(Mask a, Mask b) { return {_kandn_mask8(a.m, b.m)}; }  // ~a & b
  static uint32_t bits(Mask a) { return uint32_t(a.m); }
};
