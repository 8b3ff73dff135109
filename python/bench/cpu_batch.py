#!/usr/bin/env python3
"""CpuRuntime.trace from Python against the best C++ batch on the same rays, printed as JSON
(docs/python.md#host-arrays-and-the-c-batch); no GPU needed.

  python_ms:        wall time of CpuRuntime.trace(origins, directions, out=out) in Python (numpy
                    float32 arrays in, a preallocated record array out).
  arrays_batch_ms:  the C++ call that trace makes, alone (last_ray_pass["ms"]): tsah::closestHits of
                    tsah::RayArrays into the output's memory.
  struct_batch_ms:  tsah::closestHits on a batch of tsah::Ray structs made beforehand (a C++ caller
                    holding its own Ray array), results in a new std::vector.
  rate_ratio:       min(arrays_batch_ms, struct_batch_ms) / python_ms; target >= 0.9.

Each figure is the median of --runs runs (the three calls interleaved) after one warm-up.

usage: PYTHONPATH=<module dir> python3 python/bench/cpu_batch.py [--animation FILE] [--triangles 400000]
           [--rays 2000000] [--runs 5] [--layout bvh8] [--threads 0]
"""
import argparse
import json
import statistics
import time

import numpy as np

import tsah


def random_rays(animation, time_, count, seed=1):
    """Rays from around the frame's box toward random points inside it (about half hit)."""
    rng = np.random.default_rng(seed)
    p = animation.positions_at(time_)
    lo, hi = p.min(axis=0), p.max(axis=0)
    targets = lo + rng.random((count, 3), dtype=np.float32) * (hi - lo)
    origins = targets + rng.normal(size=(count, 3)).astype(np.float32) * float((hi - lo).max())
    return origins.astype(np.float32), (targets - origins).astype(np.float32)


def bench_cpu(tree, animation, count, runs, layout="bvh8", threads=0):
    cpu = tsah.CpuRuntime(tree, animation, threads=threads, layout=layout)
    o, d = random_rays(animation, 0.0, count, seed=2)
    out = np.empty(count, cpu.trace(o[:1], d[:1]).dtype)

    def python_call():
        start = time.perf_counter()
        cpu.trace(o, d, out=out)
        return (time.perf_counter() - start) * 1e3, cpu.last_ray_pass["ms"]

    python_call()  # warm-up
    cpu._ray_struct_batch(o, d)[1]
    timings = []
    for _ in range(runs):
        python_ms, arrays_ms = python_call()
        timings.append((python_ms, arrays_ms, cpu._ray_struct_batch(o, d)[1]))
    python_ms, arrays_ms, struct_ms = (statistics.median(t[k] for t in timings) for k in range(3))
    cxx_ms = min(arrays_ms, struct_ms)
    return {"rays": count, "layout": cpu.layout, "threads": threads, "python_ms": python_ms,
            "arrays_batch_ms": arrays_ms, "struct_batch_ms": struct_ms, "cxx_batch_ms": cxx_ms,
            "python_mrays_s": count / python_ms / 1e3, "cxx_mrays_s": count / cxx_ms / 1e3,
            "rate_ratio": cxx_ms / python_ms, "target": ">= 0.9", "met": cxx_ms / python_ms >= 0.9,
            "hits": int((out["triangle"] >= 0).sum())}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--animation", help="an animation file tsah.load reads (default: a generated wave)")
    parser.add_argument("--triangles", type=int, default=400000)
    parser.add_argument("--rays", type=int, default=2_000_000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--layout", default="bvh8")
    parser.add_argument("--threads", type=int, default=0)
    args = parser.parse_args()
    animation = tsah.load(args.animation) if args.animation else tsah.generate("wave", triangles=args.triangles,
                                                                               frames=10, seed=1)
    tree = tsah.optimize(animation, method="sah0")
    result = {"animation": args.animation or f"generated wave, {args.triangles} triangles",
              "triangles": animation.triangle_count,
              "cpu": bench_cpu(tree, animation, args.rays, args.runs, args.layout, args.threads)}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
