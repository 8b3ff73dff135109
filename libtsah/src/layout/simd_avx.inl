// V8: eight float lanes with AVX intrinsics (the V interface of wide_kernels.inl). Included inside
// the instruction-set namespace of wide_kernels_avx2.cpp; no includes here.
struct V8 {
  static constexpr uint32_t N = 8;
  __m256 v;
  struct Mask {
    __m256 m;
    friend Mask operator&(Mask a, Mask b) { return {_mm256_and_ps(a.m, b.m)}; }
    friend Mask operator|(Mask a, Mask b) { return {_mm256_or_ps(a.m, b.m)}; }
  };
  static V8 set1(float x) { return {_mm256_set1_ps(x)}; }
  static V8 load(const float* p) { return {_mm256_load_ps(p)}; }
  static void store(float* p, V8 a) { _mm256_store_ps(p, a.v); }
  friend V8 operator+(V8 a, V8 b) { return {_mm256_add_ps(a.v, b.v)}; }
  friend V8 operator-(V8 a, V8 b) { return {_mm256_sub_ps(a.v, b.v)}; }
  friend V8 operator*(V8 a, V8 b) { return {_mm256_mul_ps(a.v, b.v)}; }
  friend V8 operator/(V8 a, V8 b) { return {_mm256_div_ps(a.v, b.v)}; }
  static V8 min(V8 a, V8 b) { return {_mm256_min_ps(a.v, b.v)}; }  // a < b ? a : b
  static V8 max(V8 a, V8 b) { return {_mm256_max_ps(a.v, b.v)}; }  // a > b ? a : b
  static V8 abs(V8 a) { return {_mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v)}; }
  static Mask lt(V8 a, V8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)}; }
  static Mask le(V8 a, V8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
  static Mask gt(V8 a, V8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)}; }
  static Mask andNot(Mask a, Mask b) { return {_mm256_andnot_ps(a.m, b.m)}; }  // ~a & b
  static uint32_t bits(Mask a) { return uint32_t(_mm256_movemask_ps(a.m)); }
};
