// V4: four float lanes with SSE2 intrinsics (the V interface of wide_kernels.inl). Included inside
// an instruction-set namespace by wide_kernels_sse.cpp and wide_kernels_avx2.cpp (where the same
// code is VEX-encoded); no includes here.
struct V4 {
  static constexpr uint32_t N = 4;
  __m128 v;
  struct Mask {
    __m128 m;
    friend Mask operator&(Mask a, Mask b) { return {_mm_and_ps(a.m, b.m)}; }
    friend Mask operator|(Mask a, Mask b) { return {_mm_or_ps(a.m, b.m)}; }
  };
  static V4 set1(float x) { return {_mm_set1_ps(x)}; }
  static V4 load(const float* p) { return {_mm_load_ps(p)}; }
  static void store(float* p, V4 a) { _mm_store_ps(p, a.v); }
  friend V4 operator+(V4 a, V4 b) { return {_mm_add_ps(a.v, b.v)}; }
  friend V4 operator-(V4 a, V4 b) { return {_mm_sub_ps(a.v, b.v)}; }
  friend V4 operator*(V4 a, V4 b) { return {_mm_mul_ps(a.v, b.v)}; }
  friend V4 operator/(V4 a, V4 b) { return {_mm_div_ps(a.v, b.v)}; }
  static V4 min(V4 a, V4 b) { return {_mm_min_ps(a.v, b.v)}; }  // a < b ? a : b
  static V4 max(V4 a, V4 b) { return {_mm_max_ps(a.v, b.v)}; }  // a > b ? a : b
  static V4 abs(V4 a) { return {_mm_andnot_ps(_mm_set1_ps(-0.0f), a.v)}; }
  static Mask lt(V4 a, V4 b) { return {_mm_cmplt_ps(a.v, b.v)}; }
  static Mask le(V4 a, V4 b) { return {_mm_cmple_ps(a.v, b.v)}; }
  static Mask gt(V4 a, V4 b) { return {_mm_cmpgt_ps(a.v, b.v)}; }
  static Mask andNot(Mask a, Mask b) { return {_mm_andnot_ps(a.m, b.m)}; }  // ~a & b
  static uint32_t bits(Mask a) { return uint32_t(_mm_movemask_ps(a.m)); }
};
