#pragma once
// TSAH_HD marks functions that are compiled for both host and device, so the small POD types
// (Vec3, Aabb, node layouts, Woop triangles, rays, hits) have one definition on CPU and GPU.
#if defined(__CUDACC__)
#define TSAH_HD __host__ __device__ __forceinline__
#else
#define TSAH_HD inline
#endif
